"""Sweeps, Sobol' analyses and multi-start optimisations sharded over a Dask distributed cluster:
``hybc.dask.sweep(model, points, client=...)``, ``hybc.dask.sobol(model, problem, outputs, n, ...)``,
``hybc.dask.optimize(model, free, minimize, subject_to, starts=N, ...)``.

Same points, keywords and result as :meth:`hybc.Model.sweep`, and the result equals the local
sweep exactly (every point is an independent run; a run's result depends only on its point).

How it is split: shards are index ranges ``[start, stop)``. Given points (one C-ordered float64
matrix) are scattered once to every worker and each task names its range; for
:class:`hybc.Samples` only the sampler's description travels and each task draws its own range
of the seeded stream (the same points as the whole draw). Each worker process keeps one
:class:`hybc.Model` per model text in a module-level cache, and the model keeps one compiled form
per gradient set, so a worker compiles once however many shards it runs. The shards' columns are
concatenated in input order.

:func:`sobol` shards the rows of the Saltelli design the same way: only the analysis's
description travels, each task computes its rows from their indices (``hybc::sobol::Design``) and
returns their outputs; the client puts them end to end in row order and runs the same estimator
as :meth:`hybc.Model.sobol`, so the indices are identical to the local ones.

With :func:`optimize` each task runs a range of the starts of the same seeded draw (only the
problem's arguments travel) and returns its report; the client merges them
(``hybc::optimize::merge_shards``: the optima grouped again over every start, the
reported end from the shard that ran it), so the report equals :meth:`hybc.Model.optimize`'s
with the same ``starts`` and ``seed``, timings apart (``stats.optimize_seconds`` adds the
shards' times).

Each task runs its shard on one thread unless ``threads=`` is given: the parallelism comes from
Dask's worker processes and threads. Dask is an optional dependency (``pip install ./python[dask]``).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

import json

from . import _hybc
from ._model import Model, Samples, SobolResult, SobolSpec, _sobol_spec, _check_counts, normalise_points, sobol_result, sweep_matrix

# One Model per (text, file name) in this process (a Dask worker). Guarded: a worker runs tasks
# on several threads.
_MODELS: dict[tuple[str, str], Model] = {}
_MODELS_LOCK = threading.Lock()


def sweep(
    model: Model,
    points: Mapping[str, Any] | np.ndarray,
    *,
    client: Any = None,
    names: Sequence[str] | None = None,
    shards: int | None = None,
    **kw: Any,
) -> dict[str, np.ndarray]:
    """:meth:`hybc.Model.sweep` on a Dask cluster.

    ``client``: a ``distributed.Client`` (default: the current one). ``shards``: the number of
    tasks (default: four per worker thread, at most one per point). Other keywords as
    :meth:`hybc.Model.sweep` (``grad``, ``events``, ``t_end``, ``rtol``, ...).
    """
    from distributed import default_client

    client = client if client is not None else default_client()
    kw = {"threads": 1, **kw}
    sampled = isinstance(points, Samples)
    if sampled:
        # Only the sampler's description travels; each task draws its own rows.
        if names is not None:
            raise TypeError("names= is for a 2-D array of points; Samples names its parameters")
        names, first = points.rows(model, 0, min(points.n, 1))
        matrix, fixed, n = first, dict(points.fixed), points.n
    else:
        names, matrix, fixed = normalise_points(model, points, names)
        n = len(matrix)
    # Every error a task could raise (points, keywords, gradient names) is raised here first
    # (for samples: their ranges; every drawn value lies within them).
    sweep_matrix(model, names, matrix, fixed, {**kw, "check_only": True})
    if n == 0:
        return sweep_matrix(model, names, matrix, fixed, kw)
    if shards is None:
        slots = sum(client.nthreads().values()) or 1
        shards = 4 * slots
    if not isinstance(shards, int) or shards < 1:
        raise ValueError(f"shards: expected a positive integer, found {shards!r}")
    bounds = np.linspace(0, n, min(shards, n) + 1).round().astype(np.int64)
    if sampled:
        source = points
    else:
        [source] = client.scatter([matrix], broadcast=True)
    futures = [
        client.submit(
            _sweep_shard, model.source, model.file_name, names, source, int(a), int(b), fixed, kw,
            pure=False,
        )
        for a, b in zip(bounds[:-1], bounds[1:])
    ]
    parts = client.gather(futures)
    return {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}


def sobol(
    model: Model,
    problem: Mapping[str, Any],
    outputs: Sequence[str],
    n: int,
    *,
    client: Any = None,
    shards: int | None = None,
    seed: int = 0,
    second_order: bool = False,
    bootstrap: int = 100,
    on_fail: str = "error",
    fixed: Mapping[str, float] | None = None,
    **kw: Any,
) -> SobolResult:
    """:meth:`hybc.Model.sobol` on a Dask cluster, with an identical result.

    ``client``: a ``distributed.Client`` (default: the current one). ``shards``: the number of
    tasks (default: four per worker thread, at most one per row), each a range of the design's
    rows. Other arguments as :meth:`hybc.Model.sobol` (``t_end``, ``rtol``, ...; ``threads``
    per task, default 1).
    """
    from distributed import default_client

    client = client if client is not None else default_client()
    spec = _sobol_spec(model, problem, outputs, n, seed, second_order, bootstrap, on_fail, fixed)
    kw = {"threads": 1, **kw}
    _check_counts(kw)
    # Every error a task could raise (problem, outputs, options) is raised here first.
    model._native.sobol_evaluate(*spec.design_args(), spec.outputs, 0, 0, check_only=True, **kw)
    if shards is None:
        shards = 4 * (sum(client.nthreads().values()) or 1)
    if not isinstance(shards, int) or isinstance(shards, bool) or shards < 1:
        raise ValueError(f"shards: expected a positive integer, found {shards!r}")
    bounds = np.linspace(0, spec.rows, min(shards, spec.rows) + 1).round().astype(np.int64)
    futures = [
        client.submit(_sobol_shard, model.source, model.file_name, spec, int(a), int(b), kw, pure=False)
        for a, b in zip(bounds[:-1], bounds[1:])
    ]
    parts = client.gather(futures)
    values = np.concatenate([part[0] for part in parts])
    return sobol_result(spec, values, [(part[1], part[2]) for part in parts])


def _sobol_shard(
    text: str, file_name: str, spec: SobolSpec, start: int, stop: int, kw: dict[str, Any]
) -> tuple[np.ndarray, list[tuple[str, int]], int | None]:
    """The outputs of rows ``[start, stop)`` of the design, computed on this worker from their
    indices, with the runs that ended early among them."""
    model = _worker_model(text, file_name)
    return model._native.sobol_evaluate(*spec.design_args(), spec.outputs, start, stop, **kw)

def optimize(
    model: Model,
    free: Sequence[str],
    minimize: str,
    subject_to: Sequence[str] | str = (),
    *,
    starts: int,
    seed: int = 0,
    client: Any = None,
    shards: int | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    params: Mapping[str, Any] | None = None,
    max_iter: int = 200,
    kkt_tol: float = 1e-6,
    xtol: float = 1e-10,
    ftol: float = 1e-12,
    solver: str = "auto",
    **options: Any,
) -> dict[str, Any]:
    """:meth:`hybc.Model.optimize` with its ``starts`` on a Dask cluster, with the same report
    (the distinct optima over every start, best first, each with its event sequence and the
    starts that reached it) and ``"run"`` at the reported point.

    ``client``: a ``distributed.Client`` (default: the current one). ``shards``: the number of
    tasks (default: one per worker thread, at most one per start), each a range of the starts,
    run on one thread. Other arguments as :meth:`hybc.Model.optimize`.
    """
    from distributed import default_client

    client = client if client is not None else default_client()
    problem = model._optimize_problem(
        free, minimize, subject_to, bounds, params, starts, seed, 1, max_iter, kkt_tol, xtol, ftol, solver, options
    )
    if shards is None:
        shards = sum(client.nthreads().values()) or 1
    if not isinstance(shards, int) or isinstance(shards, bool) or shards < 1:
        raise ValueError(f"shards: expected a positive integer, found {shards!r}")
    # A problem the library refuses (a constraint, a start outside its bounds) raises in every
    # task; Dask raises the first on the client with its type and message.
    cuts = np.linspace(0, starts, min(shards, starts) + 1).round().astype(np.int64)
    futures = [
        client.submit(
            _optimize_shard, model.source, model.file_name, problem.args, problem.options, int(a), int(b),
            pure=False,
        )
        for a, b in zip(cuts[:-1], cuts[1:])
    ]
    reports = client.gather(futures)
    merged = json.loads(_hybc.optimize_merge(model._native, problem.free, problem.bounds, reports))
    return model._with_run(merged, problem)


def _optimize_shard(
    text: str, file_name: str, args: tuple, options: dict[str, Any], first: int, last: int
) -> str:
    """The JSON report of starts ``[first, last)`` of the optimisation ``args``, on this worker."""
    model = _worker_model(text, file_name)
    return _hybc.optimize_report(model._native, *args, shard=(first, last), **options)


def _worker_model(text: str, file_name: str) -> Model:
    key = (text, file_name)
    with _MODELS_LOCK:
        model = _MODELS.get(key)
        if model is None:
            model = _MODELS[key] = Model(text, file_name=file_name)
        return model


def _sweep_shard(
    text: str,
    file_name: str,
    names: list[str],
    source: np.ndarray | Samples,
    start: int,
    stop: int,
    fixed: dict[str, float],
    kw: dict[str, Any],
) -> dict[str, np.ndarray]:
    """Runs points ``[start, stop)`` of ``source`` (the points, or the sampler that draws them) on
    this worker (one compiled model per worker process and gradient set)."""
    model = _worker_model(text, file_name)
    if isinstance(source, Samples):
        names, rows = source.rows(model, start, stop)
    else:
        # Arrays that arrive through Dask's serialisation may be read-only or unaligned.
        rows = np.require(source[start:stop], np.float64, ["C", "A"])
    return sweep_matrix(model, names, rows, fixed, kw)


def _cache_info() -> list[tuple[str, list[list[str]]]]:
    """The models cached in this process and their compiled gradient sets (for tests)."""
    with _MODELS_LOCK:
        return [(m.name, m._native.compiled_grad_sets) for m in _MODELS.values()]
