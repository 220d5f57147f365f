"""hybc: hybrid dynamical models with exact gradients through events.

The native module ``hybc._hybc`` (Rust, python/src/) does the work; this package gives it a
NumPy-shaped API. ``hybc.dask`` (sweeps on a Dask cluster) and ``hybc.jax`` (a JAX primitive) are
imported on demand, so that neither Dask nor JAX is needed to import ``hybc``.
"""

from ._hybc import ModelError, ParameterError, Run, __version__
from ._model import Model, Samples, SobolError, SobolResult, grid

__all__ = ["Model", "ModelError", "ParameterError", "Run", "Samples", "SobolError", "SobolResult", "grid", "__version__"]
