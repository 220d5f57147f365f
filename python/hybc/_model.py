"""`hybc.Model`: a checked model, compiled on demand once per gradient set."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from . import _hybc


class Model:
    """A hybrid model parsed and checked from `.hyb` text.

    ``Model(text)`` or ``Model.from_file(path)``; a bad model raises :class:`hybc.ModelError`
    whose message is the rendered diagnostic (file:line:column, the line and a caret).
    Compiling happens at the first run with a given gradient set and is cached.
    """

    __slots__ = ("_native",)

    def __init__(self, text: str, *, file_name: str = "model.hyb"):
        self._native = _hybc.Model(text, file_name)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str]) -> "Model":
        """Reads, parses and checks a model file (diagnostics name the path as given)."""
        model = cls.__new__(cls)
        model._native = _hybc.Model.from_file(os.fspath(path))
        return model

    # Pickled as its text, so that Dask workers (and multiprocessing) rebuild it; each process
    # then compiles it once per gradient set.
    def __reduce__(self) -> tuple[Any, ...]:
        return (_from_source, (self._native.source, self._native.file_name))

    def __repr__(self) -> str:
        return f"<hybc.Model {self.name!r} from {self.file_name!r}>"

    @property
    def name(self) -> str:
        return self._native.name

    @property
    def source(self) -> str:
        """The model text."""
        return self._native.source

    @property
    def file_name(self) -> str:
        return self._native.file_name

    @property
    def params(self) -> dict[str, float]:
        """Parameter defaults, in declaration order."""
        return dict(self._native.params)

    @property
    def param_ranges(self) -> dict[str, tuple[float, float]]:
        """Declared ranges ``(lo, hi)`` of the parameters that declare one."""
        return dict(self._native.param_ranges)

    @property
    def states(self) -> list[str]:
        return self._native.states

    @property
    def outputs(self) -> list[str]:
        return self._native.outputs

    @property
    def events(self) -> list[str]:
        """Declared event names, in declaration order."""
        return self._native.events

    @property
    def modes(self) -> list[str]:
        return self._native.modes

    @property
    def vectors(self) -> list[tuple[str, int]]:
        """Vector parameters (``param u[N]``) and their lengths, in declaration order; their
        elements are in :attr:`params` as ``u[0]`` .."""
        return self._native.vectors

    def simulate(
        self,
        params: Mapping[str, float] | None = None,
        *,
        grad: Sequence[str] = (),
        trajectory: None | str | float = None,
        **options: Any,
    ) -> "_hybc.Run":
        """One run at ``params`` (the others at their defaults). A vector parameter (``param
        u[N]``) takes a 1-D array of its N values (``params={"u": np.zeros(N)}``), or one element
        by name (``{"u[3]": 1.0}``); in ``grad`` its name means every element, ``u[0]`` ..

        ``grad``: parameters to differentiate with respect to (the gradient column order).
        ``trajectory``: None, ``"steps"`` (every accepted step and both sides of every event) or a
        sampling interval ``dt``. ``options``: ``t_end``, ``rtol``, ``atol``, ``max_events``,
        ``max_steps``, ``method`` (``"auto"``, ``"dopri5"``, ``"dop853"``, or the Rosenbrock
        methods for stiff models ``"rodas5p"``, ``"rodas4"``), ``graze_tol``,
        ``sens_error_control``, ``h_max``; unset ones come from the model's ``simulate`` line, then
        the defaults of ``hybc run``. The GIL is released while the model compiles and runs.
        """
        _check_counts(options)
        vectors = dict(self._native.vectors)
        return self._native.simulate(
            _param_dict(_expand_vectors(params, vectors)),
            grad=_expand_names(_names(grad, "grad"), vectors),
            trajectory=trajectory,
            **options,
        )

    def sweep(
        self,
        points: Mapping[str, Any] | np.ndarray,
        *,
        names: Sequence[str] | None = None,
        grad: Sequence[str] = (),
        events: int = 5,
        threads: int = 0,
        **options: Any,
    ) -> dict[str, np.ndarray]:
        """Runs many points in parallel (GIL released); returns the columns of ``hybc sweep``.

        ``points``: a dict ``name -> 1-D array`` (all of one length; point ``i`` takes element
        ``i`` of each, as ``zip``) where a scalar value fixes that parameter for every point; or a
        2-D array of shape (n_points, len(names)) with ``names``. Any memory order or dtype that
        converts to float64 is accepted (it is normalised to C-ordered float64 first). For a full
        grid see :func:`hybc.grid`. ``events``: event slots per row (``event<k>``, ``t<k>``,
        ``dt<k>/d<p>``); ``threads``: worker threads (0: one per core). ``options`` as in
        :meth:`simulate` (no trajectory).

        Columns: float64 (NaN where ``hybc sweep`` leaves a cell empty), ``events`` int64,
        ``status``/``event<k>``/``error`` str ("" where empty).
        """
        names, matrix, fixed = normalise_points(self, points, names)
        return sweep_matrix(self, names, matrix, fixed, dict(grad=grad, events=events, threads=threads, **options))


def sweep_matrix(
    model: Model, names: list[str], matrix: np.ndarray, fixed: dict[str, float], kw: dict[str, Any]
) -> dict[str, np.ndarray]:
    """The sweep of the rows of ``matrix`` (normalised points) with keywords ``kw``."""
    kw = dict(kw)
    kw["grad"] = _names(kw.get("grad", ()), "grad")
    _check_counts(kw)
    columns = model._native.sweep(names, matrix, fixed, **kw)
    return {name: _column(v) for name, v in columns.items()}


class Samples:
    """``n`` points drawn uniformly and reproducibly: the points of ``hybc sweep --samples n
    --seed seed`` (ChaCha8, documented in the README's "Sweeps"), usable as sweep points.

    ``ranges``: ``{name: (lo, hi)}`` in draw order, ``{name: None}`` for the declared range;
    omitted, every parameter that declares a range (as ``hybc sweep --samples`` without
    ``--vary``). ``fixed``: values for every point (``--set``). :func:`hybc.dask.sweep` draws each
    shard's points on its worker (only index ranges travel).
    """

    __slots__ = ("n", "seed", "ranges", "fixed")

    def __init__(
        self,
        n: int,
        *,
        seed: int = 0,
        ranges: Mapping[str, tuple[float, float] | None] | None = None,
        fixed: Mapping[str, float] | None = None,
    ):
        self.n = int(n)
        self.seed = int(seed)
        self.ranges = None if ranges is None else {
            str(k): (None if v is None else (float(v[0]), float(v[1]))) for k, v in ranges.items()
        }
        self.fixed = _param_dict(fixed, "fixed")

    def __repr__(self) -> str:
        return f"hybc.Samples({self.n}, seed={self.seed}, ranges={self.ranges}, fixed={self.fixed})"

    def rows(self, model: "Model", start: int = 0, stop: int | None = None) -> tuple[list[str], np.ndarray]:
        """The sampled names and points ``[start, stop)``, one row per point."""
        ranges = None if self.ranges is None else list(self.ranges.items())
        stop = self.n if stop is None else stop
        names, matrix = model._native.sample_points(self.n, self.seed, ranges, start, stop)
        return names, matrix

    def points(self, model: "Model") -> dict[str, np.ndarray]:
        """The sampled points as a dict name -> array."""
        names, matrix = self.rows(model)
        return {name: matrix[:, j].copy() for j, name in enumerate(names)}


def normalise_points(
    model: Model, points: Mapping[str, Any] | np.ndarray | Samples, names: Sequence[str] | None = None
) -> tuple[list[str], np.ndarray, dict[str, float]]:
    """``(names, matrix, fixed)``: the varied parameters, one C-ordered float64 row per point,
    and the parameters fixed for every point."""
    if isinstance(points, Samples):
        if names is not None:
            raise TypeError("names= is for a 2-D array of points; Samples names its parameters")
        sampled, matrix = points.rows(model)
        return sampled, matrix, dict(points.fixed)
    if isinstance(points, Mapping):
        if names is not None:
            raise TypeError("names= is for a 2-D array of points; a dict names its columns")
        fixed: dict[str, float] = {}
        columns: dict[str, np.ndarray] = {}
        for name, value in points.items():
            array = np.asarray(value)
            # float() and NumPy would turn "0.9" into 0.9: text is not a parameter value.
            if array.dtype.kind not in "iuf":
                raise TypeError(f"points: `{name}`: expected numbers, found {value!r}")
            if array.ndim == 0:
                fixed[str(name)] = float(array)
            elif array.ndim == 1:
                columns[str(name)] = array
            else:
                raise ValueError(
                    f"points[{name!r}]: expected a scalar or a 1-D array, found shape {array.shape}"
                )
        if not columns:
            raise ValueError(
                "points: no 1-D array to vary (scalars fix a parameter for every point); "
                "for one point use simulate"
            )
        lengths = {name: len(a) for name, a in columns.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"points: the arrays differ in length: {lengths}")
        n = next(iter(lengths.values()), 0)
        matrix = np.empty((n, len(columns)), dtype=np.float64)
        for j, array in enumerate(columns.values()):
            matrix[:, j] = _float64(array, j)
        return list(columns), matrix, fixed
    if names is None:
        raise TypeError("a 2-D array of points needs names= (one per column)")
    matrix = _float64(points, "points")
    if matrix.ndim != 2:
        raise ValueError(f"points: expected a 2-D array (n_points, n_names), found shape {matrix.shape}")
    return [str(n) for n in names], matrix, {}


_COUNTS = ("events", "threads", "max_events", "max_steps")


def _check_counts(kw: Mapping[str, Any]) -> None:
    """Integer keywords: a clear error naming the keyword rather than an overflow."""
    for name in _COUNTS:
        value = kw.get(name)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name}: expected a non-negative integer, found {value!r}")
        # The caps themselves (hybc::limits) are checked by the native side, as the CLI's.


def _float64(array: Any, what: Any) -> np.ndarray:
    """C-contiguous, aligned float64 (a Fortran-ordered, strided or unaligned array is copied)."""
    try:
        return np.require(array, np.float64, ["C", "A"])
    except (TypeError, ValueError) as e:
        raise ValueError(f"points {what}: cannot be read as float64 numbers: {e}") from None


def _column(values: Any) -> np.ndarray:
    # Text columns arrive as lists of str.
    return np.array(values, dtype=str) if isinstance(values, list) else values


def _names(names: Any, what: str) -> list[str]:
    """A sequence of parameter names. A single ``str`` is refused: ``list("h0")`` would read it as
    the names ``h`` and ``0``."""
    if isinstance(names, (str, bytes)):
        raise TypeError(f"{what}: expected a sequence of parameter names such as [{str(names)!r}], found the string {names!r}")
    try:
        names = list(names)
    except TypeError:
        raise TypeError(f"{what}: expected a sequence of parameter names, found {type(names).__name__}") from None
    for name in names:
        if not isinstance(name, str):
            raise TypeError(f"{what}: expected parameter names (str), found {name!r}")
    return names


def _number(value: Any, what: str) -> float:
    """A parameter value: a real number (Python or NumPy), never a string or a bool that
    ``float()`` would quietly convert."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{what}: expected a number, found {type(value).__name__} {value!r}")
    return float(value)


def _expand_vectors(params: Any, vectors: dict[str, int]) -> Any:
    """``params`` with each vector parameter's array replaced by its elements ``u[0]`` .., after
    checking that it is 1-D with one value per element."""
    if not isinstance(params, Mapping) or not any(k in vectors for k in params):
        return params
    out: dict[str, Any] = {}
    for name, value in params.items():
        if name not in vectors:
            out[name] = value
            continue
        array = np.asarray(value)
        # float() and NumPy would turn "0.9" into 0.9: text is not a parameter value.
        if array.dtype.kind not in "iuf":
            raise TypeError(f"params: `{name}`: expected numbers, found {value!r}")
        if array.shape != (vectors[name],):
            raise ValueError(
                f"params: `{name}` is a vector of {vectors[name]} parameters: expected a 1-D array of "
                f"{vectors[name]} values, found shape {array.shape}"
            )
        for k, v in enumerate(array.tolist()):
            out[f"{name}[{k}]"] = v
    return out


def _expand_names(names: list[str], vectors: dict[str, int]) -> list[str]:
    """A vector parameter's name stands for all its elements, in order (as ``--grad u``)."""
    out: list[str] = []
    for name in names:
        out.extend([f"{name}[{k}]" for k in range(vectors[name])] if name in vectors else [name])
    return out


def _param_dict(params: Mapping[str, float] | None, what: str = "params") -> dict[str, float]:
    if params is None:
        return {}
    if not isinstance(params, Mapping):
        raise TypeError(f"{what}: expected a dict name -> value, found {type(params).__name__}")
    return {str(k): _number(v, f"{what}: `{k}`") for k, v in params.items()}


def grid(**axes: Any) -> dict[str, np.ndarray]:
    """The full grid over ``axes`` (name -> 1-D values) as sweep points: the first axis varies
    slowest and the last fastest, the order of ``hybc sweep --vary a=... --vary b=...``."""
    if not axes:
        raise ValueError("grid: give at least one axis, e.g. grid(e=np.linspace(0.6, 0.9, 10))")
    values = [np.asarray(v, dtype=np.float64) for v in axes.values()]
    for name, v in zip(axes, values):
        if v.ndim != 1:
            raise ValueError(f"grid: axis {name!r} must be 1-D, found shape {v.shape}")
    mesh = np.meshgrid(*values, indexing="ij")
    return {name: m.ravel() for name, m in zip(axes, mesh)}


def _from_source(text: str, file_name: str) -> Model:
    return Model(text, file_name=file_name)
