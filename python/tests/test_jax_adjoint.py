"""hybc.jax's reverse mode by the adjoint (issue #40, section 2): jax.grad / jax.vjp / jax.jacrev
pull cotangents back with hybc's discrete adjoint, jax.jvp / jax.jacfwd keep the forward
sensitivities, and each kind of call runs only the native work it needs (the handler's counters).

Tolerances: forward mode's sensitivities are under the error control by default, while the adjoint
differentiates the steps the values' error control chose, so the two agree to the tolerances
(1e-9 relative here, at rtol 1e-10); with ``sens_error_control=False`` forward mode takes the same
steps as the plain run and the two are the same derivative computed two ways: 1e-11.
"""

from __future__ import annotations

import os
import pathlib

import numpy as np
import pytest

try:
    import jax
except ImportError:
    if os.environ.get("HYBC_CI"):
        raise
    pytest.skip("JAX is not installed", allow_module_level=True)
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import hybc  # noqa: E402
import hybc.jax as hj  # noqa: E402

MODELS = pathlib.Path(__file__).resolve().parents[2] / "models"
TOL_CONTROLLED, TOL_SAME_STEPS = 1e-9, 1e-11
P0 = jnp.array([0.8, 1.0])

# The ball under a force control of K knots over [0, T]: events, a reset and a pwl input.
CONTROLLED = """model controlled
param g = 9.81
param e = 0.8 in [0, 1]
param h0 = 1.0
param u[{K}] = 0
state y = h0
state v = 0
der(y) = v
der(v) = -g + pwl(t, 0, 2.5, u)
event touchdown when y <= 0 {{
    v := -e * v
}}
output energy = 0.5 * v^2 + g * y
simulate t_end = 2.5, rtol = 1e-10, atol = 1e-12
"""

# x grows at rate c; at x = h event a sets x to 2 h, which is past b's guard (1.5 h): b fires at
# the same instant (a cascade, which the adjoint does not carry) and sets x to 0. Events at
# t = h/c, h/c, 2h/c, 2h/c before t_end = 2.5, and x(2.5) = 2.5 c - 2 h.
CASCADE = """model cascade
param h = 1
param c = 1
state x = 0
der(x) = c
event a when x >= h {
    x := 2 * h
}
event b when x >= 1.5 * h {
    x := 0
}
simulate t_end = 2.5, rtol = 1e-10, atol = 1e-12
"""


def controls(k: int) -> np.ndarray:
    """A smooth control of k knots (the ball bounces 5 times before t = 2.5 under it)."""
    s = np.linspace(0.0, 1.0, k)
    return 0.8 * np.sin(2 * np.pi * 3 * s) + 0.3 * s


def rel_close(a, b, rtol):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = max(float(np.max(np.abs(b))), 1e-300)
    assert np.max(np.abs(a - b)) <= rtol * scale, (np.max(np.abs(a - b)) / scale, a, b)


def delta(f, before):
    after = f.counts()
    return {key: after[key] - before[key] for key in after}


@pytest.fixture(scope="module")
def ball_model():
    return hybc.Model.from_file(MODELS / "ball.hyb")


@pytest.mark.parametrize("sec", [True, False])
def test_grad_equals_jacfwd_on_the_ball(ball_model, sec):
    f = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4, sens_error_control=sec)
    tol = TOL_CONTROLLED if sec else TOL_SAME_STEPS
    energy = lambda p: f(p)["energy"]  # noqa: E731
    rel_close(jax.grad(energy)(P0), jax.jacfwd(energy)(P0), tol)
    times = lambda p: f(p)["event_times"]  # noqa: E731
    rel_close(jax.jacrev(times)(P0), jax.jacfwd(times)(P0), tol)
    # A loss of both: one cotangent of values and of times, one backward pass.
    def loss(p):
        out = f(p)
        return out["energy"] * 0.5 + jnp.sum(out["event_times"] ** 2)

    jac_e, jac_t = jax.jacfwd(energy)(P0), jax.jacfwd(times)(P0)
    t = times(P0)
    rel_close(jax.grad(loss)(P0), 0.5 * jac_e + 2 * t @ jac_t, tol)
    # jax.vjp with cotangents of both.
    _, pull = jax.vjp(lambda p: (f(p)["energy"], f(p)["event_times"]), P0)
    w = jnp.array([1.0, -2.0, 0.5, 3.0])
    (got,) = pull((jnp.asarray(0.25), w))
    rel_close(got, 0.25 * jac_e + w @ jac_t, tol)


def test_grad_runs_the_adjoint_and_no_forward_sensitivities(ball_model):
    f = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4)
    before = f.counts()
    jax.block_until_ready(jax.grad(lambda p: f(p)["energy"])(P0))
    assert delta(f, before) == {"plain": 1, "forward": 0, "adjoint": 1, "recorded": 1, "transposed": 0}
    before = f.counts()
    jax.block_until_ready(jax.jacfwd(lambda p: f(p)["energy"])(P0))
    assert delta(f, before) == {"plain": 1, "forward": 1, "adjoint": 0, "recorded": 0, "transposed": 0}
    # jax.jacrev: one cotangent per row, all at one point: one recorded run, one backward pass
    # for the 4 rows (the handler groups equal points).
    before = f.counts()
    jax.block_until_ready(jax.jacrev(lambda p: f(p)["event_times"])(P0))
    assert delta(f, before) == {"plain": 1, "forward": 0, "adjoint": 4, "recorded": 1, "transposed": 0}
    # sens="forward": reverse mode through the forward Jacobians, as before the adjoint.
    g = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4, sens="forward")
    before = g.counts()
    grad = jax.grad(lambda p: g(p)["energy"])(P0)
    assert delta(g, before) == {"plain": 1, "forward": 1, "adjoint": 0, "recorded": 0, "transposed": 1}
    rel_close(grad, jax.grad(lambda p: f(p)["energy"])(P0), TOL_CONTROLLED)


def test_a_bad_reverse_mode_is_refused(ball_model):
    with pytest.raises(ValueError, match=r'sens: expected "forward", "adjoint" or "auto", found "backward"'):
        hj.function(ball_model, params=["e"], outputs=["energy"], sens="backward")


@pytest.mark.parametrize("sec", [True, False])
def test_grad_equals_jacfwd_under_a_200_knot_control(sec):
    model = hybc.Model(CONTROLLED.format(K=200))
    f = hj.function(model, params=["u", "e", "h0"], outputs=["energy"], events=6, sens_error_control=sec)
    p = jnp.concatenate([jnp.asarray(controls(200)), P0])
    assert hj.status_name(f(p)["status"]) == "ok" and int(f(p)["n_events"]) == 5
    tol = TOL_CONTROLLED if sec else TOL_SAME_STEPS
    def loss(p):
        out = f(p)
        return out["energy"] + 3.0 * out["event_times"][2] - out["event_times"][4]

    before = f.counts()
    grad = jax.grad(loss)(p)
    assert delta(f, before)["adjoint"] == 1 and delta(f, before)["forward"] == 0
    rel_close(grad, jax.jacfwd(loss)(p), tol)
    # The control moves the energy: the gradient is not trivially zero on the knots.
    assert np.count_nonzero(np.asarray(grad[:200])) > 100


def test_vmap_of_grad_is_three_grads_in_one_native_call(ball_model):
    f = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4)
    def loss(p):
        out = f(p)
        return out["energy"] + jnp.sum(out["event_times"])

    points = jnp.array([[0.8, 1.0], [0.7, 1.2], [0.75, 0.9]])
    batched = jax.vmap(jax.grad(loss))(points)
    for point, row in zip(points, batched):
        np.testing.assert_allclose(row, jax.grad(loss)(point), rtol=1e-14)
    assert ffi_calls(jax.make_jaxpr(jax.vmap(jax.grad(loss)))(points).jaxpr) == {
        "values": 1,
        "pull_back": 1,
    }
    assert ffi_calls(jax.make_jaxpr(jax.vmap(jax.jacfwd(loss)))(points).jaxpr) == {
        "values": 1,
        "with_jacobians": 1,
    }
    # vmap of jacfwd still equals vmap of grad (forward and reverse through one batching rule).
    rel_close(jax.vmap(jax.jacfwd(loss))(points), batched, TOL_CONTROLLED)
    # The pull-back of a batch larger than the serial threshold runs on the pool: same numbers.
    many = jnp.stack([jnp.linspace(0.7, 0.9, 9), jnp.linspace(0.8, 1.2, 9)], axis=-1)
    np.testing.assert_allclose(
        jax.jit(jax.vmap(jax.grad(loss)))(many)[:3], jax.vmap(jax.grad(loss))(many[:3]), rtol=1e-14
    )


def ffi_calls(jaxpr) -> dict[str, int]:
    """The FFI calls a jaxpr makes (also inside the jaxprs of its equations' parameters), by kind:
    their result count tells them apart (4 values, 6 with Jacobians, 1 a pull-back). A loop
    primitive (while, scan) would make a batch several native calls: none may appear."""
    kinds = {4: "values", 6: "with_jacobians", 1: "pull_back"}
    found: dict[str, int] = {}

    def walk(j):
        for eqn in j.eqns:
            assert eqn.primitive.name not in ("while", "scan"), eqn.primitive.name
            if eqn.primitive.name == "ffi_call":
                kind = kinds[len(eqn.outvars)]
                found[kind] = found.get(kind, 0) + 1
            for value in eqn.params.values():
                for sub in value if isinstance(value, (list, tuple)) else [value]:
                    inner = getattr(sub, "jaxpr", sub)
                    if hasattr(inner, "eqns"):
                        walk(inner)

    walk(jaxpr)
    return found


def carried_by_the_adjoint(model, grad, **options) -> bool:
    """Whether the library's adjoint carries this run (`hybc run --sens adjoint` falls back to
    forward sensitivities, and says so, where it does not)."""
    return model.simulate(grad=grad, sens="adjoint", **options).sens == "adjoint"


def check_path(f, before, carried):
    """The pull-back went where the library says: the adjoint, or the forward Jacobians after a
    recorded run the backward pass refused."""
    ran = delta(f, before)
    assert ran["recorded"] == 1
    if carried:
        assert ran["adjoint"] == 1 and ran["forward"] == 0 and ran["transposed"] == 0, ran
    else:
        assert ran["adjoint"] == 0 and ran["forward"] == 1 and ran["transposed"] == 1, ran


def test_a_cascade_gets_the_right_grad():
    """The issue's example of a run the adjoint did not carry at first (a reset that puts x on
    another event's guard); right either way."""
    model = hybc.Model(CASCADE)
    f = hj.function(model, params=["h", "c"], outputs=["x"], events=4)
    p = jnp.array([1.0, 1.0])
    out = f(p)
    assert int(out["n_events"]) == 4
    before = f.counts()
    grad = jax.grad(lambda p: f(p)["x"])(p)
    check_path(f, before, carried_by_the_adjoint(model, ["h", "c"]))
    np.testing.assert_allclose(grad, [-2.0, 2.5], rtol=1e-9)
    # Event times k h / c: d/dh = k / c, d/dc = -k h / c^2 (k = 1, 1, 2, 2).
    k = np.array([1.0, 1.0, 2.0, 2.0])
    np.testing.assert_allclose(
        jax.jacrev(lambda p: f(p)["event_times"])(p), np.stack([k, -k], axis=1), rtol=1e-9
    )


def test_a_run_the_adjoint_refuses_gets_the_right_grad(ball_model):
    """Rosenbrock steps, refused by the adjoint when this was written (the handler then pulls back
    through the forward Jacobians) and carried since: `check_path` follows whichever path the
    library says it takes; the ball's closed form dE/de = 8 g h0 e^7 either way. A run the
    adjoint still refuses (`--at` samples, an event on an input knot) would test the fallback
    again."""
    f = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4, method="rodas5p")
    before = f.counts()
    grad = jax.grad(lambda p: f(p)["energy"])(P0)
    check_path(f, before, carried_by_the_adjoint(ball_model, ["e", "h0"], method="rodas5p"))
    np.testing.assert_allclose(grad, [8 * 9.81 * 0.8**7, 9.81 * 0.8**8], rtol=1e-6)
    rel_close(grad, jax.jacfwd(lambda p: f(p)["energy"])(P0), TOL_CONTROLLED)


def test_a_stop_event_seeds_the_total_derivative():
    """y at a time-triggered stop at ts: y = h0 - g ts^2 / 2, dy/dts = -g ts, dy/dh0 = 1."""
    model = hybc.Model(
        "model s\nparam g = 9.81\nparam h0 = 10\nparam ts = 1\nstate y = h0\nstate v = 0\n"
        "der(y) = v\nder(v) = -g\noutput y2 = y * y\nevent done when t >= ts {\n    stop\n}\n"
    )
    f = hj.function(model, params=["ts", "h0"], outputs=["y", "y2", "v"], events=1, t_end=5.0)
    p = jnp.array([1.2, 10.0])
    before = f.counts()
    def values(p):
        out = f(p)
        return jnp.stack([out["y"], out["y2"], out["v"]])

    rows = jax.jacrev(values)(p)
    assert delta(f, before)["adjoint"] == 3
    y = 10.0 - 9.81 * 1.2**2 / 2
    np.testing.assert_allclose(rows[0], [-9.81 * 1.2, 1.0], rtol=1e-9)
    np.testing.assert_allclose(rows[1], [2 * y * -9.81 * 1.2, 2 * y], rtol=1e-9)
    np.testing.assert_allclose(rows[2], [-9.81, 0.0], rtol=1e-9, atol=1e-12)


def test_samples_and_pads_pull_back_right(ball_model):
    # at= samples: the adjoint seeds each sample's cotangent where its walk reaches the sample.
    # y(0.3) = h0 - g 0.3^2 / 2 before the first bounce (dy/dh0 = 1, dy/de = 0); y(0.9) after it.
    at = np.array([0.3, 0.9])
    f = hj.function(ball_model, params=["e", "h0"], outputs=["y"], at=at, events=6, t_end=2.0)
    def loss(p):
        out = f(p)
        return jnp.sum(out["samples"]["y"]) + jnp.nansum(out["event_times"])

    before = f.counts()
    grad = jax.grad(loss)(P0)
    assert delta(f, before)["adjoint"] == 1 and delta(f, before)["transposed"] == 0
    rel_close(grad, jax.jacfwd(loss)(P0), TOL_CONTROLLED)
    first = lambda p: f(p)["samples"]["y"][0]  # noqa: E731
    rel_close(jax.grad(first)(P0), jnp.array([0.0, 1.0]), 1e-12)
    # The same numbers as forward mode taking the same steps (no sensitivity error control).
    same = hj.function(ball_model, params=["e", "h0"], outputs=["y"], at=at, events=6, t_end=2.0,
                       sens_error_control=False)
    def loss_same(p):
        out = same(p)
        return jnp.sum(out["samples"]["y"]) + jnp.nansum(out["event_times"])

    rel_close(jax.grad(loss_same)(P0), jax.jacfwd(loss_same)(P0), TOL_SAME_STEPS)
    # Unfired slots (3 bounces before t = 2, 6 slots): a cotangent on a pad goes nowhere.
    g = hj.function(ball_model, params=["e", "h0"], outputs=["y"], events=6, t_end=2.0)
    weights = jnp.arange(1.0, 7.0)
    # The loss reads NaN (the pads), but its gradient exists: a pad's derivative is 0.
    pads = lambda p: weights @ g(p)["event_times"]  # noqa: E731
    before = g.counts()
    got = jax.grad(pads)(P0)
    assert delta(g, before)["adjoint"] == 1
    assert np.all(np.isfinite(got))
    rel_close(got, jax.jacfwd(pads)(P0), TOL_CONTROLLED)


def test_bad_params_give_nan_cotangents(ball_model):
    f = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4)
    grads = jax.vmap(jax.grad(lambda p: f(p)["energy"]))(jnp.array([[0.8, 1.0], [1.5, 1.0]]))
    assert np.all(np.isfinite(grads[0])) and np.all(np.isnan(grads[1]))


POLY = (
    "model poly\nparam a0 = 1\nparam a1 = 1\nparam a2 = 1\nparam a3 = 1\nparam a4 = 1\nparam a5 = 1\n"
    "state x = 0\nder(x) = a0 + a1 * t + a2 * t^2 + a3 * t^3 + a4 * t^4 + a5 * t^5\n"
    "output q = x\nsimulate t_end = 1\n"
)


def test_auto_takes_the_adjoint_from_six_inputs():
    """sens="auto": one cotangent row against m inputs, hybc run --sens auto's rule (rows < m / 5).

    x(1) = sum_k a_k / (k + 1): the gradient is exact whichever way it is pulled back."""
    model = hybc.Model(POLY)
    five = hj.function(model, params=["a0", "a1", "a2", "a3", "a4"], outputs=["q"], sens="auto")
    six = hj.function(model, params=["a0", "a1", "a2", "a3", "a4", "a5"], outputs=["q"], sens="auto")
    before5, before6 = five.counts(), six.counts()
    g5 = jax.grad(lambda p: five(p)["q"])(jnp.ones(5))
    g6 = jax.grad(lambda p: six(p)["q"])(jnp.ones(6))
    assert delta(five, before5)["transposed"] == 1 and delta(five, before5)["adjoint"] == 0
    assert delta(six, before6)["adjoint"] == 1 and delta(six, before6)["forward"] == 0
    want = 1.0 / np.arange(1, 7)
    rel_close(g5, want[:5], TOL_CONTROLLED)
    rel_close(g6, want, TOL_CONTROLLED)


def test_vmap_of_jacrev_equals_vmap_of_jacfwd(ball_model):
    f = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4)

    def values(p):
        out = f(p)
        return jnp.concatenate([out["event_times"], out["energy"][None]])

    points = jnp.array([[0.8, 1.0], [0.7, 1.2]])
    before = f.counts()
    rev = jax.vmap(jax.jacrev(values))(points)
    # 2 points x 5 rows pulled back, each point's rows in one recorded run and backward pass.
    assert delta(f, before) == {"plain": 2, "forward": 0, "adjoint": 10, "recorded": 2, "transposed": 0}
    rel_close(rev, jax.vmap(jax.jacfwd(values))(points), TOL_CONTROLLED)


def test_a_first_pull_back_in_a_parallel_batch(ball_model):
    """A fresh model's first pull-backs run on the pool (8 points > the serial 4): the adjoint's
    kernels are built on first use by whichever worker comes first, and every point still gets
    the gradient a later serial call gives."""
    model = hybc.Model(ball_model.source)
    f = hj.function(model, params=["e", "h0"], outputs=["energy"], events=4, t_end=2.0)
    points = jnp.stack([jnp.linspace(0.7, 0.9, 8), jnp.linspace(0.9, 1.3, 8)], axis=-1)
    batched = jax.vmap(jax.grad(lambda p: f(p)["energy"]))(points)
    assert f.counts()["adjoint"] == 8
    for point, row in zip(points, batched):
        np.testing.assert_allclose(row, jax.grad(lambda p: f(p)["energy"])(point), rtol=1e-14)


def test_a_stop_event_time_and_the_values_at_it_in_one_cotangent():
    """Stop at x = h with x' = c from x(0) = 0: t_stop = h / c; y' = 1, so y = t_stop.
    loss = 2 y + 3 t_stop = 5 h / c: d/dh = 5 / c, d/dc = -5 h / c^2."""
    model = hybc.Model(
        "model stopat\nparam h = 2\nparam c = 4\nstate x = 0\nstate y = 0\nder(x) = c\n"
        "der(y) = 1\nevent hit when x >= h {\n    stop\n}\n"
    )
    f = hj.function(model, params=["h", "c"], outputs=["y"], events=1, t_end=5.0)

    def loss(p):
        out = f(p)
        return 2.0 * out["y"] + 3.0 * out["event_times"][0]

    p = jnp.array([2.0, 4.0])
    before = f.counts()
    grad = jax.grad(loss)(p)
    assert delta(f, before)["adjoint"] == 1
    np.testing.assert_allclose(grad, [5.0 / 4.0, -5.0 * 2.0 / 16.0], rtol=1e-10)
    rel_close(grad, jax.jacfwd(loss)(p), TOL_CONTROLLED)
