"""`hybc.Model`: a checked model, compiled on demand once per gradient set."""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from . import _hybc


class Model:
    """A hybrid model parsed and checked from `.hyb` text.

    ``Model(text)``, ``Model.from_file(path)`` or ``Model.from_sbml(path)``; a bad model raises :class:`hybc.ModelError`
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

    @classmethod
    def from_sbml(cls, path: str | os.PathLike[str]) -> "Model":
        """Imports an SBML file (Level 2 or 3) and checks the `.hyb` model it becomes (docs/sbml.md).

        What the importer refuses raises :class:`hybc.ModelError` naming each element at the
        path's line and column, with the reason.
        """
        model = cls.__new__(cls)
        model._native = _hybc.Model.from_sbml(os.fspath(path))
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
        at: Sequence[float] | np.ndarray | None = None,
        of: Sequence[str] | None = None,
        **options: Any,
    ) -> "_hybc.Run":
        """One run at ``params`` (the others at their defaults). A vector parameter (``param
        u[N]``) takes a 1-D array of its N values (``params={"u": np.zeros(N)}``), or one element
        by name (``{"u[3]": 1.0}``); in ``grad`` its name means every element, ``u[0]`` ..

        ``grad``: parameters to differentiate with respect to (the gradient column order).
        ``trajectory``: None, ``"steps"`` (every accepted step and both sides of every event) or a
        sampling interval ``dt``. ``at``: ascending times within the run at which every output
        and state is reported with its derivatives, from the dense output (``run.samples``:
        ``values[time, name]``, ``dvalues[time, name, param]``; a time at an event instant gets
        the values after its events). ``of``: only these quantities get gradients (``hybc run
        --of``): states and outputs by name, ``EVENT#K``, ``EVENT#last``, ``NAME@TIME`` (sampled
        as ``at`` would); the others' are left out of ``dstate``, ``doutputs`` and the event
        gradients, and ``sens="adjoint"`` runs one backward pass per quantity. ``options``: ``t_end``, ``rtol``, ``atol``, ``max_events``,
        ``max_steps``, ``method`` (``"auto"``, ``"dopri5"``, ``"dop853"``, or the Rosenbrock
        methods for stiff models ``"rodas5p"``, ``"rodas4"``), ``graze_tol``,
        ``sens_error_control``, ``quadrature_error_control`` (``True``: running costs under the
        step-size control, ``--quadrature-error-control``; by default they are out of it), ``land_events`` (``True``: every method
        retakes a step to land on each event, ``--land-events``; ``False``: none does; unset: the
        Rosenbrock methods do, the explicit ones where stability holds the step), ``h_max``; unset ones come from the
        model's ``simulate`` line, then the defaults of ``hybc run``. The same keywords, with the
        same checks, go with :meth:`sweep`, :meth:`sobol`, :meth:`fit`, :meth:`optimize` and
        ``hybc.jax``. The GIL is released while the model compiles and runs.
        """
        _check_counts(options)
        vectors = dict(self._native.vectors)
        return self._native.simulate(
            _param_dict(_expand_vectors(params, vectors)),
            grad=_expand_names(_names(grad, "grad"), vectors),
            trajectory=trajectory,
            at=None if at is None else np.asarray(at, dtype=np.float64).ravel().tolist(),
            of=None if of is None else _names(of, "of", "quantity names"),
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
        ``i`` of each, as ``zip``) where a scalar value fixes that parameter for every point (a
        vector parameter ``u[N]`` takes an array of shape (N,), fixed for every point, or
        (n_points, N), row ``i`` for point ``i``; in ``grad`` its name means every element); or a
        2-D array of shape (n_points, len(names)) with ``names``. Any memory order or dtype that
        converts to float64 is accepted (it is normalised to C-ordered float64 first). For a full
        grid see :func:`hybc.grid`. ``events``: event slots per row (``event<k>``, ``t<k>``,
        ``dt<k>/d<p>``); ``threads``: worker threads (0: one per core). ``options`` as in
        :meth:`simulate` (no trajectory), but ``sens`` defaults to ``"auto"`` as for ``hybc sweep``
        (the adjoint at points whose reported quantities are fewer than a fifth of the ``grad``
        parameters).

        Columns: float64 (NaN where ``hybc sweep`` leaves a cell empty), ``events`` int64,
        ``status``/``event<k>``/``error`` str ("" where empty).
        """
        names, matrix, fixed = normalise_points(self, points, names)
        grad = _expand_names(_names(grad, "grad"), dict(self._native.vectors))
        return sweep_matrix(self, names, matrix, fixed, dict(grad=grad, events=events, threads=threads, **options))

    def sobol(
        self,
        problem: Mapping[str, Any],
        outputs: Sequence[str],
        n: int,
        *,
        seed: int = 0,
        second_order: bool = False,
        bootstrap: int = 100,
        on_fail: str = "error",
        fixed: Mapping[str, float] | None = None,
        threads: int = 0,
        **options: Any,
    ) -> "SobolResult":
        """Sobol' indices of ``outputs`` over the priors of SALib's ``problem`` (the runs of
        ``hybc sobol``, in parallel with the GIL released).

        ``problem``: ``{"names": [...], "bounds": [[a, b], ...], "dists": [...]}`` (``dists``
        optional, default uniform) with SALib's distribution names: ``"unif"`` and ``"logunif"``
        (bounds ``[lower, upper]``), ``"norm"`` (``[mean, sd]``), ``"lognorm"`` (``[mean, sd]`` of
        the log); a prior must stay within the parameter's declared range. ``outputs``: outputs or
        states (final values), ``"EVENT#K"`` (time of the K-th firing), ``"EVENT#last"``. ``n``:
        base points; the model runs ``n (D + 2)`` times, ``n (2 D + 2)`` with ``second_order``.
        ``seed`` seeds the scrambled Sobol' sequence and the bootstrap; ``bootstrap``: resamples
        for the intervals (0: none); ``on_fail``: ``"error"``, ``"drop"`` or ``"value=X"``, what
        to do with rows without a value (docs/sobol.md). ``fixed``: values of other parameters;
        ``threads`` (0: one per core) and ``options`` (``t_end``, ``rtol``, ...) as in
        :meth:`sweep`.

        Returns a :class:`SobolResult`: per output a dict with SALib's keys (``S1``, ``S1_conf``,
        ``ST``, ``ST_conf``, and ``S2``, ``S2_conf`` with ``second_order``) and the counts. An output
        without indices (under ``on_fail="error"`` any row without a value; under ``"drop"``
        fewer than 2 base points left) raises :class:`SobolError`, whose ``result`` holds the
        other outputs' indices.
        """
        spec = _sobol_spec(self, problem, outputs, n, seed, second_order, bootstrap, on_fail, fixed)
        _check_counts({"threads": threads, **options})
        values, early, first = self._native.sobol_evaluate(
            *spec.design_args(), spec.outputs, 0, spec.rows, threads=threads, **options
        )
        return sobol_result(spec, values, [(early, first)])

    def fit(
        self,
        free: Sequence[str],
        targets: Sequence[str] | Mapping[str, float] = (),
        *,
        data: Mapping[str, Any] | None = None,
        params: Mapping[str, Any] | None = None,
        max_iter: int = 100,
        xtol: float = 1e-10,
        gtol: float = 1e-10,
        ftol: float = 1e-14,
        **options: Any,
    ) -> dict[str, Any]:
        """Fits the parameters ``free`` (bounded by their declared ranges; a vector parameter's
        name means every element) by least squares, as ``hybc fit`` does, and returns its report
        (the dict of ``hybc fit --format json``: ``params``, ``converged``, ``reason``,
        ``residuals``, ``condition``, ``cusps``, ``data`` with the residuals per name and the
        standard errors, ``stats``).

        - ``targets``: ``"NAME=VALUE[@W]"`` strings (``NAME`` an output or state at the end,
          ``NAME@TIME``, ``EVENT#K``, ``EVENT#last``), or a dict ``NAME -> VALUE``.
        - ``data``: measurements, a DataFrame-like mapping of columns: ``"time"``, one column per
          observed output or state, optional ``"sigma_NAME"`` columns (standard deviations);
          NaN is a missing value. The rules and messages are ``hybc fit --data``'s (rows are
          numbered as lines of that CSV: the header is line 1).
        - ``params``: start values of the free parameters and values of the others.
        - ``options``: the keywords of :meth:`simulate` (``t_end``, ``rtol``, ...).

        A fit that does not converge returns its report with ``converged`` False and the
        ``reason``; a target or data the model refuses raises ``ValueError``; a run that fails at
        the start raises ``RuntimeError``. Warnings (fewer targets than free parameters) go
        through :mod:`warnings`.
        """
        vectors = dict(self._native.vectors)
        free = _expand_names(_names(free, "free"), vectors)
        if isinstance(targets, Mapping):
            targets = [f"{name}={_number(value, f'targets: `{name}`')!r}" for name, value in targets.items()]
        elif isinstance(targets, str):
            targets = [targets]
        else:
            targets = [str(t) for t in targets]
        _check_counts({"max_iter": max_iter, **options})
        report, notes = _hybc.fit_report(
            self._native,
            free,
            targets,
            None if data is None else _data_csv(data),
            _param_dict(_expand_vectors(params, vectors)),
            int(max_iter),
            float(xtol),
            float(gtol),
            float(ftol),
            **options,
        )
        for note in notes:
            warnings.warn(note, stacklevel=2)
        return json.loads(report)

    def optimize(
        self,
        free: Sequence[str],
        minimize: str,
        subject_to: Sequence[str] | str = (),
        *,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        params: Mapping[str, Any] | None = None,
        starts: int = 1,
        seed: int = 0,
        threads: int = 0,
        max_iter: int = 200,
        kkt_tol: float = 1e-6,
        xtol: float = 1e-10,
        ftol: float = 1e-12,
        solver: str = "auto",
        **options: Any,
    ) -> dict[str, Any]:
        """Minimises ``minimize`` over the parameters ``free`` subject to the constraints
        ``subject_to``, as ``hybc optimize`` does (see docs/optimize.md), and returns
        its report, the dict of ``hybc optimize --format json`` (``optimum``, ``params``,
        ``objective_value``, ``constraints`` with their multipliers, ``converged``, ``reason``,
        ``kkt``, ``optima`` from several starts with their event sequences, ``set``,
        ``sequence_changes``, ``cusp_notes``, ``stats`` ...), with ``"run"``: the
        :meth:`simulate` run at the reported point, with gradients with respect to ``free``.

        - ``minimize``: an output or a state at the end, ``EVENT#K``, ``EVENT#last``,
          ``NAME@TIME`` or a parameter.
        - ``subject_to``: ``"Q = V"``, ``"Q <= V"``, ``"Q >= V"``; a path constraint
          ``"y@0:2:41 >= 0"`` holds at 41 times.
        - ``bounds``: ``name -> (lo, hi)`` within the declared ranges (a vector's name for every
          element); the declared ranges otherwise.
        - ``params``: the start of the free parameters and the values of the others;
          ``starts - 1`` more starts are drawn (``seed``) within the bounds, run on ``threads``
          (:func:`hybc.dask.optimize` runs them on a Dask cluster, with the same report).
        - ``solver``: ``"slsqp"`` (general constraints, at most 1000 free parameters),
          ``"lbfgsb"`` (bounds only, at most 100000), ``"auto"`` (L-BFGS-B for bounds only above
          20 free parameters, else SLSQP); the report's ``solver`` says which ran.
        - ``options``: the keywords of :meth:`simulate` (``t_end``, ``rtol``, ...).

        A problem that does not converge returns its report with ``converged`` False and the
        ``reason``; names or constraints the model refuses raise ``ValueError``.
        """
        problem = self._optimize_problem(
            free, minimize, subject_to, bounds, params, starts, seed, threads, max_iter, kkt_tol, xtol, ftol, solver,
            options,
        )
        report = json.loads(_hybc.optimize_report(self._native, *problem.args, **problem.options))
        return self._with_run(report, problem)

    def _optimize_problem(
        self, free, minimize, subject_to, bounds, params, starts, seed, threads, max_iter, kkt_tol, xtol, ftol, solver,
        options,
    ) -> "_OptimizeProblem":
        """The checked arguments of ``_hybc.optimize_report`` (shared with ``hybc.dask.optimize``)."""
        vectors = dict(self._native.vectors)
        free = _expand_names(_names(free, "free"), vectors)
        subject_to = [subject_to] if isinstance(subject_to, str) else [str(c) for c in subject_to]
        if bounds is not None and not isinstance(bounds, Mapping):
            raise TypeError(f"bounds: expected a dict name -> (lo, hi), found {type(bounds).__name__}")
        boxes = None
        if bounds is not None:
            boxes = {}
            for name, box in bounds.items():
                lo, hi = box
                boxes[str(name)] = (_number(lo, f"bounds: `{name}`"), _number(hi, f"bounds: `{name}`"))
        _check_counts({"starts": starts, "threads": threads, "max_iter": max_iter, "seed": seed, **options})
        args = (
            free,
            str(minimize),
            subject_to,
            boxes,
            _param_dict(_expand_vectors(params, vectors)),
            int(max_iter),
            float(kkt_tol),
            float(xtol),
            float(ftol),
            int(starts),
            int(seed),
            int(threads),
            str(solver),
        )
        return _OptimizeProblem(free, boxes, args, dict(options))

    def _with_run(self, report: dict[str, Any], problem: "_OptimizeProblem") -> dict[str, Any]:
        """``report`` with ``"run"``: the run at its reported point, with gradients w.r.t. ``free``."""
        report["run"] = self.simulate(report["params"], grad=problem.free, **problem.options)
        return report

    def periodic(
        self,
        section: str,
        free: Sequence[str],
        *,
        params: Mapping[str, Any] | None = None,
        max_iter: int = 50,
        tol: float = 1e-10,
        **options: Any,
    ) -> dict[str, Any]:
        """A periodic orbit through events and its Floquet multipliers, as ``hybc periodic`` finds
        it (docs/periodic.md): the initial state the run returns to right after the section event
        ``section`` fires (``"EVENT"``, or ``"EVENT#K"`` for its K-th firing), solved for by Newton's
        method over the parameters ``free`` (a vector's name for every element) from ``params``
        (their start and the other parameters' values). Returns the dict of ``hybc periodic --format
        json``: ``found``, ``fixed_point``, ``params`` (the free ones), ``period``, ``multipliers``
        (``[re, im]`` pairs, largest first), ``trivial``, ``stable``, ``stability`` (``"stable"``,
        ``"unstable"`` or ``"borderline"``), ``neutral_band``, ``orbit``, ``monodromy``,
        ``iterations``, ``residuals``, ``events``, ``verification``.

        - ``max_iter``: the most Newton iterations (one run each); ``tol``: converged when every
          state returns within ``tol (1 + |x0|)`` of its initial value.
        - ``options``: the keywords of :meth:`simulate` (``t_end``, ``rtol``, ...).

        An unknown section or free parameter raises ``ValueError`` (``hybc.ParameterError`` for a
        name); no orbit found (a run that misses the section, Newton not converging, its point not
        coming back in a run of the model, a Jacobian that is not finite) raises ``RuntimeError``
        with the words of ``hybc periodic``, whose ``report`` is the dict ``hybc periodic --format
        json`` prints then (``found`` false, the ``reason``).
        """
        if not isinstance(section, str):
            raise TypeError(f"section: expected an event name, found {section!r}")
        vectors = dict(self._native.vectors)
        free = _expand_names(_names(free, "free"), vectors)
        _check_counts({"max_iter": max_iter, **options})
        try:
            report = _hybc.periodic_report(
                self._native,
                section,
                free,
                _param_dict(_expand_vectors(params, vectors)),
                int(max_iter),
                float(tol),
                **options,
            )
        except RuntimeError as e:
            # A search that found nothing: the dict `hybc periodic --format json` prints then.
            if isinstance(getattr(e, "report", None), str):
                e.report = json.loads(e.report)
            raise
        return json.loads(report)

    def sobol_design(
        self,
        problem: Mapping[str, Any],
        n: int,
        *,
        seed: int = 0,
        second_order: bool = False,
        fixed: Mapping[str, float] | None = None,
    ) -> np.ndarray:
        """The rows :meth:`sobol` runs with these arguments: the varied parameters' values, one
        row per run (``n (D + 2)`` rows, ``n (2 D + 2)`` with ``second_order``) in SALib's order
        (``A, AB_1 .. AB_D, [BA_1 .. BA_D], B`` per base point), columns in ``problem["names"]``
        order: the ``X`` of ``SALib.sample.sobol.sample``, from hybc's own scrambled sequence."""
        spec = _sobol_spec(self, problem, ("",), n, seed, second_order, 0, "error", fixed)
        return self._native.sobol_design(*spec.design_args(), 0, spec.rows)


class SobolError(ValueError):
    """An output has no indices: rows without a value under ``on_fail="error"``, or fewer than
    2 base points left under ``"drop"``. The message names each such output and its counts;
    ``result`` is the
    :class:`SobolResult` (the refused outputs hold ``error`` and ``Y`` only)."""

    def __init__(self, message: str, result: "SobolResult"):
        super().__init__(message)
        self.result = result


class SobolSpec(NamedTuple):
    """A checked Sobol' analysis, as it travels to Dask workers (no model, no values)."""

    names: list[str]
    priors: list[tuple[str, str, list[float]]]
    outputs: list[str]
    n: int
    rows: int
    second_order: bool
    seed: int
    bootstrap: int
    on_fail: str
    fixed: dict[str, float]

    def design_args(self) -> tuple[Any, ...]:
        return (self.priors, self.n, self.second_order, self.seed, self.fixed)


class SobolResult(dict):
    """Sobol' indices per output: ``result["energy"]["S1"]``. A dict output name -> dict with
    SALib's keys as NumPy arrays (``S1``, ``ST`` of shape (D,), ``S1_conf``, ``ST_conf`` the
    half-widths of the 95% intervals, 1.96 bootstrap standard errors, absent with
    ``bootstrap=0``; with ``second_order`` ``S2`` and ``S2_conf`` of shape (D, D), NaN off the
    upper triangle as SALib's), ``variance``, ``failed_rows`` (rows without a value),
    ``dropped_base_points``, ``base_points`` (used), ``on_fail`` (the policy applied) and ``Y``
    (the output at every row of the design, NaN where none: the ``Y`` SALib's analyze takes), or
    ``error`` and ``Y`` for an output ``on_fail="error"`` refused.

    Attributes: ``names`` (the varied parameters, in ``problem`` order), ``n``, ``runs``,
    ``second_order``, ``seed``, ``bootstrap``, ``on_fail``, ``conf_level`` (0.95),
    ``ended_early`` (runs that did not end as asked, by status word: ``{"zeno": 12}``) and
    ``first_ended_early_row`` (1-based, None if none)."""

    __slots__ = (
        "names", "n", "runs", "second_order", "seed", "bootstrap", "on_fail", "conf_level",
        "ended_early", "first_ended_early_row",
    )

    def __repr__(self) -> str:
        early = ", ".join(f"{w} {c}" for w, c in self.ended_early.items()) or "none"
        lines = [f"<hybc.SobolResult over {', '.join(self.names)}: n = {self.n}, {self.runs} runs, "
                 f"ended early: {early}, on_fail={self.on_fail!r}>"]
        for label, r in self.items():
            if "error" in r:
                lines.append(f"  {label}: {r['error']}")
            else:
                lines.append(f"  {label}: S1 {np.round(r['S1'], 4)}, ST {np.round(r['ST'], 4)} "
                             f"({r['failed_rows']} rows without a value)")
        return "\n".join(lines)


def _count(value: Any, what: str, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{what}: expected an integer >= {low}, found {value!r}")
    return int(value)


def _salib_priors(problem: Any) -> list[tuple[str, str, list[float]]]:
    """``(name, dist, bounds)`` per parameter of SALib's ``problem`` dict, its shape checked here
    (the distributions and numbers are checked by the native side, with the model)."""
    if not isinstance(problem, Mapping):
        raise TypeError(f"problem: expected SALib's dict with names and bounds, found {type(problem).__name__}")
    if problem.get("groups") is not None:
        raise ValueError("problem: groups are not supported; hybc's indices are per parameter")
    for key in ("names", "bounds"):
        if key not in problem:
            raise ValueError(f"problem: no {key!r}; SALib's problem has 'names' and 'bounds'")
    names = _names(problem["names"], "problem['names']")
    if not names:
        raise ValueError("problem: 'names' is empty; vary at least one parameter")
    if "num_vars" in problem and problem["num_vars"] != len(names):
        raise ValueError(f"problem: num_vars is {problem['num_vars']!r} for {len(names)} names")
    bounds = problem["bounds"]
    dists = problem.get("dists")
    dists = ["unif"] * len(names) if dists is None else list(dists)
    for key, entries in (("bounds", bounds), ("dists", dists)):
        if isinstance(entries, (str, bytes)) or len(entries) != len(names):
            raise ValueError(f"problem: {key} has {len(entries)} entries for {len(names)} names")
    priors = []
    for i, (name, b, dist) in enumerate(zip(names, bounds, dists)):
        if not isinstance(dist, str):
            raise TypeError(f"problem: dists[{i}]: expected a distribution name, found {dist!r}")
        if isinstance(b, (str, bytes)) or not isinstance(b, Sequence | np.ndarray):
            raise TypeError(f"problem: bounds[{i}]: expected a list of numbers, found {b!r}")
        priors.append((name, dist, [_number(v, f"problem: bounds[{i}]") for v in b]))
    return priors


def _sobol_spec(
    model: Model, problem: Any, outputs: Any, n: Any, seed: Any, second_order: Any, bootstrap: Any,
    on_fail: Any, fixed: Any,
) -> SobolSpec:
    """The checked arguments of :meth:`Model.sobol` (the native side checks them again, with the
    model: names, ranges, priors, outputs, caps)."""
    priors = _salib_priors(problem)
    outputs = _names(outputs, "outputs")
    n = _count(n, "n", 2)
    if not isinstance(second_order, bool):
        raise TypeError(f"second_order: expected True or False, found {second_order!r}")
    if not isinstance(on_fail, str):
        raise TypeError(f'on_fail: expected "error", "drop" or "value=X", found {on_fail!r}')
    if n & (n - 1):
        warnings.warn(f"n = {n} is not a power of 2; the Sobol' points are balanced at powers of 2",
                      stacklevel=3)
    d = len(priors)
    rows = n * (2 * d + 2 if second_order else d + 2)
    return SobolSpec(
        names=[p[0] for p in priors], priors=priors, outputs=outputs, n=n, rows=rows,
        second_order=second_order, seed=_count(seed, "seed"), bootstrap=_count(bootstrap, "bootstrap"),
        on_fail=on_fail.strip(), fixed=_param_dict(fixed, "fixed"),
    )


def sobol_result(spec: SobolSpec, values: np.ndarray, tallies: list[tuple[Any, Any]]) -> SobolResult:
    """The indices of ``values`` (every row of the design, in order) by the library's
    estimators, and the tallies of runs that ended early, one per shard, added up."""
    analysed = _hybc.sobol_analyze(
        np.ascontiguousarray(values), spec.outputs, len(spec.priors), spec.second_order, spec.on_fail,
        spec.bootstrap, spec.seed,
    )
    result = SobolResult()
    early: dict[str, int] = {}
    firsts = []
    for words, first in tallies:
        for word, count in words:
            early[word] = early.get(word, 0) + count
        if first is not None:
            firsts.append(first)
    result.names, result.n, result.runs = list(spec.names), spec.n, spec.rows
    result.second_order, result.seed, result.bootstrap = spec.second_order, spec.seed, spec.bootstrap
    result.on_fail, result.conf_level, result.ended_early = spec.on_fail, 0.95, early
    result.first_ended_early_row = min(firsts) + 1 if firsts else None
    refused = []
    for j, (label, entry) in enumerate(zip(spec.outputs, analysed)):
        entry["Y"] = values[:, j]
        if "error" in entry:
            refused.append(entry["error"])
        else:
            entry["on_fail"] = spec.on_fail
        result[label] = entry
    if refused:
        raise SobolError("; ".join(refused), result)
    return result



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
    --seed seed`` (ChaCha8, documented in docs/sweep.md), usable as sweep points.

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
        vectors = dict(model.vectors)
        for name, value in points.items():
            array = np.asarray(value)
            # float() and NumPy would turn "0.9" into 0.9: text is not a parameter value.
            if array.dtype.kind not in "iuf":
                raise TypeError(f"points: `{name}`: expected numbers, found {value!r}")
            if name in vectors:
                # A vector parameter: (N,) fixes it for every point, (n_points, N) varies it.
                size = vectors[name]
                if array.shape == (size,):
                    fixed.update({f"{name}[{k}]": float(v) for k, v in enumerate(array.tolist())})
                elif array.ndim == 2 and array.shape[1] == size:
                    columns.update({f"{name}[{k}]": array[:, k] for k in range(size)})
                else:
                    raise ValueError(
                        f"points[{name!r}]: `{name}` is a vector of {size} parameters: expected shape "
                        f"({size},) for every point or (n_points, {size}), found {array.shape}"
                    )
            elif array.ndim == 0:
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


_COUNTS = ("events", "threads", "max_events", "max_steps", "max_iter", "starts", "seed")


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


def _names(names: Any, what: str, kind: str = "parameter names") -> list[str]:
    """A sequence of names (of parameters, or of the ``kind`` given). A single ``str`` is refused:
    ``list("h0")`` would read it as the names ``h`` and ``0``."""
    if isinstance(names, (str, bytes)):
        raise TypeError(f"{what}: expected a sequence of {kind} such as [{str(names)!r}], found the string {names!r}")
    try:
        names = list(names)
    except TypeError:
        raise TypeError(f"{what}: expected a sequence of {kind}, found {type(names).__name__}") from None
    for name in names:
        if not isinstance(name, str):
            raise TypeError(f"{what}: expected {kind} (str), found {name!r}")
    return names


def _number(value: Any, what: str) -> float:
    """A parameter value: a real number (Python or NumPy), never a string or a bool that
    ``float()`` would quietly convert."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{what}: expected a number, found {type(value).__name__} {value!r}")
    return float(value)


def _data_csv(data: Mapping[str, Any]) -> str:
    """``Model.fit``'s ``data`` (a mapping of equally long columns, e.g. a pandas DataFrame) as
    the CSV text ``hybc fit --data`` reads: NaN becomes an empty cell (a missing value), numbers
    their shortest round-trip form."""
    if not isinstance(data, Mapping) and not hasattr(data, "keys"):
        raise TypeError(f"data: expected a mapping of columns (a dict or a DataFrame), found {type(data).__name__}")
    names = [str(k) for k in data.keys()]
    for name in names:
        if any(c in name for c in ",\n\r"):
            raise ValueError(f"data: column name {name!r} contains a comma or a line break")
    columns = []
    for key, name in zip(data.keys(), names):
        array = np.asarray(data[key])
        if array.dtype.kind not in "iuf":
            raise TypeError(f"data: column `{name}`: expected numbers, found dtype {array.dtype}")
        if array.ndim != 1:
            raise ValueError(f"data: column `{name}`: expected a 1-D column, found shape {array.shape}")
        columns.append(array.astype(np.float64))
    lengths = {name: len(c) for name, c in zip(names, columns)}
    if len(set(lengths.values())) > 1:
        raise ValueError(f"data: the columns differ in length: {lengths}")
    cell = lambda v: "" if np.isnan(v) else repr(float(v))  # noqa: E731
    lines = [",".join(names)]
    lines.extend(",".join(cell(v) for v in row) for row in zip(*columns))
    return "\n".join(lines) + "\n"


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


class _OptimizeProblem:
    """An optimisation's checked arguments: the free names (vectors expanded), the bounds, the
    positional arguments of ``_hybc.optimize_report`` and the simulation keywords."""

    __slots__ = ("free", "bounds", "args", "options")

    def __init__(self, free: list[str], bounds: dict | None, args: tuple, options: dict[str, Any]):
        self.free, self.bounds, self.args, self.options = free, bounds, args, options
