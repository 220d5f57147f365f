"""hybc.jax: a hybc model as a JAX function with exact derivatives through events.

::

    import jax, jax.numpy as jnp, hybc, hybc.jax
    jax.config.update("jax_enable_x64", True)
    model = hybc.Model.from_file("models/ball.hyb")
    f = hybc.jax.function(model, params=["e", "h0"], outputs=["energy"], events=4, t_end=2.5)
    out = f(jnp.array([0.8, 1.0]))   # {"energy": (), "event_times": (4,), "n_events": (), "status": ()}
    jax.grad(lambda p: f(p)["energy"])(jnp.array([0.8, 1.0]))

The function runs natively through one XLA FFI target (the handler is Rust, in
``python/src/jax_ffi/``). Its derivative is a ``jax.custom_jvp`` whose tangent map is a linear
function with a transpose of its own (``jax.custom_derivatives.linear_call``), so each mode runs
what suits it:

- forward mode (``jax.jvp``, ``jax.jacfwd``) multiplies the Jacobians hybc's forward
  sensitivities give (saltation through every event): one run with one sensitivity column per
  input;
- reverse mode (``jax.grad``, ``jax.vjp``, ``jax.jacrev``) never forms the Jacobian: the
  transpose pulls each cotangent back by hybc's discrete adjoint (the run recorded without
  sensitivities, then one backward pass for every cotangent at that point: the rows of
  ``jax.jacrev`` share one run and one pass), so ``jax.grad`` of one loss runs a plain run, a
  recorded run and one backward pass, and no sensitivity column whatever the number of inputs
  (what a backward pass costs: docs/performance.md). Where the adjoint does
  not carry a run (what ``hybc run --sens adjoint`` does not carry yet, docs/cli.md: an
  event on input knots where the flow jumps, ...; also a cotangent on a sample not reached, a run that ended
  early, or a pulled-back number that is not finite) the handler pulls back through the forward
  Jacobians instead: the numbers are right either way. ``sens="forward"`` makes reverse mode always go
  through the forward Jacobians, ``sens="auto"`` takes the adjoint from six inputs on
  (``hybc run --sens auto``'s rule for one row: fewer rows than a fifth of the parameters).

The values come from the plain run (no sensitivities) in every mode. The adjoint differentiates
the steps that run took, so it equals the forward sensitivities of a run with
``sens_error_control=False`` to round-off; forward mode keeps the sensitivities under the error
control by default, so ``jax.grad`` and ``jax.jacfwd`` agree to the tolerances (bit-close with
``sens_error_control=False``). A ``jax.vmap`` batch of either mode is one native call, run in
parallel. Derivatives are first order: a derivative of the Jacobian (``jax.hessian``) raises JAX's
"The FFI call to `hybc_run` cannot be differentiated".

Values along the trajectory: ``at=times`` reads the same outputs at each of the T times too,
from the dense output (``Model.simulate(at=)``'s samples); ``f(p)["samples"][name]`` has shape
(T,) and its JVP is the interpolated sensitivity at that fixed time, so ``jax.grad`` of a loss
over a whole time series works. A time the run did not reach (it stopped before) reads NaN.

A vector parameter (``param u[N]``) named in ``params`` is N inputs, ``u[0]`` .. ``u[N-1]``, in
order; ``f`` takes either the flat vector of every input or a dict of arrays, one per name in
``params`` (``{"u": u, "T": 2.0}``), and ``jax.grad`` then returns a dict of the same shape.

Rules:

- Shapes are static: ``events=K`` slots hold the first K event times, NaN where fewer fired;
  ``n_events`` counts every event that fired (it can exceed K).
- ``status`` (int32) says why the numbers are what they are, instead of an exception inside
  traced code; see :data:`STATUS`. The final values of a run that did not reach ``t_end``
  (Zeno, stuck, max_events, fault) are NaN, and so is every derivative that does not exist
  (grazing). A parameter outside its declared range gives ``bad_param`` and NaN everywhere.
- The derivative of an unfired (NaN) event slot is 0: the pad is a constant, so a loss that masks
  the pads gets a finite gradient.
- ``status`` describes the plain run that gave the values, in every mode: a derivative that does
  not exist (a flow whose derivative is not finite, a grazing crossing) is NaN, and
  ``not_differentiable`` is not reported (it needs the sensitivities; ``Model.simulate`` with
  ``grad=`` reports it). A cotangent of exactly 0 contributes nothing, so a NaN derivative of a
  quantity the loss does not read never reaches the gradient.
- float64 only: ``jax_enable_x64`` must be on; float32 inputs are refused.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import linear_call
from jax.extend.core import jaxpr_as_fun
from jax.interpreters import batching

try:  # the primitive behind linear_call, to give it a batching rule (see _linear_call_batcher)
    from jax._src.custom_derivatives import linear_call_p
except ImportError:  # a JAX that moved it: its own rule (if any) applies
    linear_call_p = None

from . import _hybc
from ._model import _check_counts, _expand_names, _expand_vectors, _param_dict

__all__ = ["function", "Function", "STATUS", "status_name"]

#: Status codes (the ``status`` output) and their names.
STATUS: dict[int, str] = {
    0: "ok",  # reached t_end (or a stop event); every derivative exists
    1: "grazing",  # an event grazed its guard: derivatives depending on its time are NaN
    2: "not_differentiable",  # some derivative stopped existing (NaN), values exact
    3: "zeno",  # events accumulate before t_end: final values NaN
    4: "stuck",  # the state cannot leave a guard, or events keep firing at one instant
    5: "max_events",  # max_events fired before t_end: final values NaN
    6: "fault",  # the integration failed (step size underflow, non-finite state, ...)
    7: "bad_param",  # an input is not finite or outside its declared range: all NaN
    8: "non_finite",  # reached t_end, but a final state or output is NaN or infinite
}
# The names (but bad_param, a refused input) are the words Model.simulate's Run.status and the
# sweep rows print for the same run: one vocabulary (hybc::status::RunStatus).
OK, GRAZING, NOT_DIFFERENTIABLE, ZENO, STUCK, MAX_EVENTS, FAULT, BAD_PARAM, NON_FINITE = range(9)

_TARGET = "hybc_run"
_registered = False
# Keys of the result dict that are not model outputs.
_RESERVED = ("event_times", "n_events", "status", "samples")


def status_name(code: Any) -> str:
    """The name of a status code (``"ok"``, ``"zeno"``, ...)."""
    return STATUS.get(int(code), f"unknown status {int(code)}")


def _register_target() -> None:
    global _registered
    if not _registered:
        address = _hybc.jax_handler_address()
        capsule = jax.ffi.pycapsule(ctypes.c_void_p(address))
        jax.ffi.register_ffi_target(_TARGET, capsule, platform="cpu")
        _registered = True


def _linear_call_batcher(axis_data, args, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
    """A batching rule for ``linear_call`` (JAX 0.10 has none): the callee and its transpose mapped
    with ``jax.vmap`` (so that the FFI calls inside, ``vmap_method="broadcast_all"``, stay one
    native call), and the result again a ``linear_call`` whose transpose is the mapped transpose.
    A residual without a batch dimension stays unbatched: ``jax.jacfwd`` maps the tangents only,
    and the forward Jacobians are then computed once, not once per basis tangent."""
    params = dict(
        callee=callee,
        transpose_thunk=transpose_thunk,
        num_callee_consts=num_callee_consts,
        num_res=num_res,
    )
    if all(d is None for d in dims):
        out = linear_call_p.bind(*args, **params)
        return out, [None] * len(out)
    size = axis_data.size
    k = num_callee_consts + num_res
    # Batched operands with their batch dimension first; the linear ones all batched.
    args = [a if d is None else jnp.moveaxis(a, d, 0) for a, d in zip(args, dims)]
    head, head_axes = args[:k], [None if d is None else 0 for d in dims[:k]]
    lin = [
        jnp.broadcast_to(a, (size, *jnp.shape(a))) if d is None else a for a, d in zip(args[k:], dims[k:])
    ]
    res_axes = head_axes[num_callee_consts:]
    callee_fun = jaxpr_as_fun(callee)

    def fun(head, lin):
        return jax.vmap(lambda h, x: callee_fun(*h, *x), in_axes=(head_axes, 0))(head, lin)

    def transpose(head, cts):
        t_jaxpr, t_consts = transpose_thunk()
        t_fun = jaxpr_as_fun(t_jaxpr)
        return jax.vmap(lambda r, c: t_fun(*t_consts, *r, *c), in_axes=(res_axes, 0))(
            head[num_callee_consts:], cts
        )

    out = linear_call(fun, transpose, head, lin)
    return out, [0] * len(out)


def _register_linear_call_batcher() -> None:
    """Registers :func:`_linear_call_batcher` unless this JAX batches ``linear_call`` itself (every
    rule lands in ``fancy_primitive_batchers``; ``primitive_batchers`` is a view of it)."""
    if linear_call_p is not None and linear_call_p not in batching.fancy_primitive_batchers:
        batching.fancy_primitive_batchers[linear_call_p] = _linear_call_batcher


_register_linear_call_batcher()


def _x64() -> bool:
    return bool(jax.config.read("jax_enable_x64"))


_X64_MESSAGE = (
    'hybc.jax computes in float64: call jax.config.update("jax_enable_x64", True) '
    "before building arrays"
)


class Function:
    """A hybc model as a JAX function of a parameter vector (see :func:`function`)."""

    def __init__(
        self,
        model: Any,
        params: list[str],
        outputs: list[str],
        events: int,
        handle: int,
        at: np.ndarray | None = None,
        groups: list[tuple[str, int | None]] | None = None,
    ):
        self.model = model
        self.params = params
        self.outputs = outputs
        self.events = events
        self.handle = handle
        #: The sample times (``at=``), shape (T,).
        self.at = np.zeros(0) if at is None else at
        # The names given in ``params`` and their sizes (None for a scalar), for dict inputs.
        self.groups = groups if groups is not None else [(p, None) for p in params]
        m, k = len(params), events
        n = len(outputs) * (1 + len(self.at))
        f64, i32 = jnp.float64, jnp.int32
        values = jax.ShapeDtypeStruct((n,), f64)
        times = jax.ShapeDtypeStruct((k,), f64)
        count = jax.ShapeDtypeStruct((), i32)
        plain = jax.ffi.ffi_call(
            _TARGET, (values, times, count, count), vmap_method="broadcast_all"
        )
        with_jacobians = jax.ffi.ffi_call(
            _TARGET,
            (
                values,
                jax.ShapeDtypeStruct((n, m), f64),
                times,
                jax.ShapeDtypeStruct((k, m), f64),
                count,
                count,
            ),
            vmap_method="broadcast_all",
        )
        # Reverse mode's pull-back: (p, ct_values, ct_times) -> the inputs' cotangent.
        pull_back = jax.ffi.ffi_call(
            _TARGET, jax.ShapeDtypeStruct((m,), f64), vmap_method="broadcast_all"
        )
        attr = np.int64(handle)

        @jax.custom_jvp
        def call(p):
            return plain(p, handle=attr)

        def push_forward(p, dp):
            # The linear tangent map (forward mode): the forward sensitivities' Jacobians.
            _, dv, _, dt, _, _ = with_jacobians(p, handle=attr)
            return dv @ dp, dt @ dp

        def transpose(p, cts):
            # Its transpose (reverse mode): the adjoint's backward pass, in the handler.
            ct_values, ct_times = cts
            return pull_back(p, ct_values, ct_times, handle=attr)

        @call.defjvp
        def call_jvp(primals, tangents):
            (p,), (dp,) = primals, tangents
            # The values from the plain run: under jax.grad only the transpose runs, so nothing
            # here may compute sensitivities.
            v, t, n_events, status = plain(p, handle=attr)
            dv, dt = linear_call(push_forward, transpose, p, dp)
            no_tangent = np.zeros((), dtype=jax.dtypes.float0)
            return (v, t, n_events, status), (dv, dt, no_tangent, no_tangent)

        self._call = call

    def counts(self) -> dict[str, int]:
        """How many points each kind of native work of this function (and of every identical one:
        they share a handle) ran so far: ``plain`` (values), ``forward`` (runs with forward
        sensitivities), ``adjoint`` (points whose cotangents the adjoint pulled back),
        ``recorded`` (runs recorded for the adjoint, one backward pass each: the rows of
        ``jax.jacrev`` at one point share one), ``transposed`` (points pulled back through the
        forward Jacobians). For tests and diagnostics."""
        return dict(_hybc.jax_counts(self.handle))

    def __repr__(self) -> str:
        return (
            f"<hybc.jax.Function of {self.params} -> {self.outputs}, "
            f"{self.events} event slots>"
        )

    def _flatten(self, p: Mapping[str, Any]) -> jax.Array:
        """The input vector from a dict of one array per name in ``params``."""
        names = [name for name, _ in self.groups]
        if set(p) != set(names):
            raise ValueError(f"hybc.jax: expected the inputs {names}, got {sorted(p)}")
        parts = []
        for name, size in self.groups:
            value = jnp.asarray(p[name])
            want = () if size is None else (size,)
            if value.shape != want:
                what = "a scalar" if size is None else f"a vector of {size}"
                raise ValueError(f"hybc.jax: input `{name}` is {what}, got shape {value.shape}")
            parts.append(jnp.ravel(value))
        return jnp.concatenate(parts) if parts else jnp.zeros(0)

    def __call__(self, p: Any) -> dict[str, Any]:
        """Runs at the input vector ``p`` (shape ``(len(params),)``, float64), or at a dict of
        arrays, one per name given in ``params`` (a vector parameter's array of N values).

        Returns a dict: each output (a scalar), ``"event_times"`` (K,), ``"n_events"`` and
        ``"status"`` (int32 scalars), and with ``at=`` ``"samples"``, a dict of each output at
        the sample times (T,).
        """
        if not _x64():
            raise TypeError(_X64_MESSAGE)
        if isinstance(p, Mapping):
            p = self._flatten(p)
        p = jnp.asarray(p)
        if jnp.issubdtype(p.dtype, jnp.floating) and p.dtype != jnp.float64:
            raise TypeError(f"hybc.jax: the parameters are {p.dtype}; {_X64_MESSAGE}")
        if not jnp.issubdtype(p.dtype, jnp.floating):
            p = p.astype(jnp.float64)
        m = len(self.params)
        if p.shape != (m,):
            raise ValueError(
                f"hybc.jax: expected a vector of {m} parameters ({', '.join(self.params)}), "
                f"got shape {p.shape} (map over more points with jax.vmap)"
            )
        values, times, n_events, status = self._call(p)
        c = len(self.outputs)
        out: dict[str, Any] = {name: values[i] for i, name in enumerate(self.outputs)}
        if len(self.at):
            rows = values[c:].reshape(len(self.at), c)
            out["samples"] = {name: rows[:, i] for i, name in enumerate(self.outputs)}
        out["event_times"] = times
        out["n_events"] = n_events
        out["status"] = status
        return out


def function(
    model: Any,
    params: Iterable[str],
    outputs: Iterable[str] = (),
    events: int = 0,
    *,
    values: Mapping[str, float] | None = None,
    at: Any = None,
    **sim_kw: Any,
) -> Function:
    """A JAX function ``f(p) -> dict`` running ``model`` with the parameters ``params`` as inputs.

    - ``params``: names of the input parameters, the order of ``p``'s entries (and of gradients);
      a vector parameter's name stands for its N elements.
    - ``outputs``: names of outputs (or states) read at the end of the run, or of event times
      as ``hybc fit`` spells them: ``EVENT#K`` (the K-th firing, K from 1) and ``EVENT#last``;
      an event family's element counts its own firings (``low[1]#2``). An event that fired fewer
      times reads NaN with derivative 0, as an unfired slot does; not with ``at=``.
    - ``events``: number K of event slots (``"event_times"`` has shape (K,)).
    - ``values``: values of the other parameters (their defaults otherwise; a vector parameter
      takes an array).
    - ``at``: ascending times within the run at which the outputs are read too
      (``"samples"``); at most 10^7 numbers (values and Jacobian entries) per point.
    - ``sim_kw``: the keywords of ``Model.simulate``: ``t_end``, ``rtol``, ``atol``,
      ``max_events``, ``max_steps``, ``method``, ``graze_tol``, ``sens_error_control``,
      ``quadrature_error_control``, ``land_events``, ``h_max`` (the model's ``simulate`` line and the run defaults otherwise).
    - ``sens``: how reverse mode computes: ``"adjoint"`` (the default: one backward pass per
      cotangent, the forward Jacobians where the adjoint does not carry the run), ``"forward"``
      (always through the forward Jacobians) or ``"auto"`` (the adjoint from six inputs on).
      Forward mode always runs forward sensitivities.

    The model is compiled here (twice: without and with sensitivities, each cached per model).
    A bad name or option raises at once (``hybc.ParameterError``, ``ValueError``).
    """
    if not _x64():
        raise TypeError(_X64_MESSAGE)
    params = [params] if isinstance(params, str) else list(params)
    vectors = dict(getattr(model, "_native", model).vectors)
    groups = [(name, vectors.get(name)) for name in params]
    params = _expand_names(params, vectors)
    times = None if at is None else np.asarray(at, dtype=np.float64).ravel()
    outputs = [outputs] if isinstance(outputs, str) else list(outputs)
    _check_counts({"events": events, **sim_kw})
    events = int(events)
    for name in outputs:
        if name in _RESERVED:
            raise ValueError(f"outputs: `{name}` collides with the result key of that name")
    if len(set(outputs)) != len(outputs):
        raise ValueError(f"outputs: a name is given twice in {outputs}")
    native = getattr(model, "_native", model)
    fixed = _param_dict(_expand_vectors(values, vectors), "values")
    if sim_kw.get("sens") is None:
        sim_kw["sens"] = "adjoint"
    handle = _hybc.jax_register(
        native, params, outputs, events, fixed, at=None if times is None else times.tolist(), **sim_kw
    )
    _register_target()
    return Function(model, params, outputs, events, handle, times, groups)
