"""hybc.jax against closed forms (../shared/reference/closed-forms.md): values, jax.grad,
jax.jacfwd / jax.jacrev, jax.vmap, jax.jit, jax.lax.fori_loop, and the statuses that replace
silent numbers (grazing, Zeno, bad parameters, NaN-padded event slots).

Tolerances: the runs use rtol 1e-10, atol 1e-12 (the ball's `simulate` line); event times and
values are compared at a relative 1e-8, derivatives at 1e-7 (sensitivities carry the same error
control, and a derivative divides by a crossing speed of order 1 here).
"""

from __future__ import annotations

import math
import os
import pathlib

import numpy as np
import pytest

try:
    import jax
except ImportError:
    # In CI (HYBC_CI set by .ci/run) a missing JAX is a failure, not a skip.
    if os.environ.get("HYBC_CI"):
        raise
    pytest.skip("JAX is not installed", allow_module_level=True)
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import hybc  # noqa: E402
import hybc.jax as hj  # noqa: E402

MODELS = pathlib.Path(__file__).resolve().parents[2] / "models"
G, E, H0, T = 9.81, 0.8, 1.0, 2.5
VALUE_RTOL, GRAD_RTOL = 1e-8, 1e-7


def ball_closed_form(e: float, h0: float, t_end: float, g: float = G):
    """Bounce times before t_end, their derivatives d/de and d/dh0, and E(t_end) with d/de, d/dh0.

    t_k = t1 + (2 v1 / g) sum_{i=1}^{k-1} e^i with t1 = sqrt(2 h0 / g), v1 = sqrt(2 g h0);
    E = g h0 e^(2k) after k bounces. The bounces accumulate at t* = t1 + 2 e v1 / (g (1 - e)):
    t_end must come before it.
    """
    v1 = math.sqrt(2 * g * h0)
    t1 = math.sqrt(2 * h0 / g)
    assert t_end < zeno_time(e, h0, g), "infinitely many bounces before t_end"
    times, dt_de, dt_dh0 = [], [], []
    k = 0
    while True:
        s = sum(e**i for i in range(1, k + 1))
        ds = sum(i * e ** (i - 1) for i in range(1, k + 1))
        t = t1 + 2 * v1 / g * s
        if t >= t_end:
            break
        times.append(t)
        dt_de.append(2 * v1 / g * ds)
        dt_dh0.append((1 + 2 * s) / v1)
        k += 1
    energy = g * h0 * e ** (2 * k)
    d_energy = (2 * k * g * h0 * e ** (2 * k - 1) if k else 0.0, g * e ** (2 * k))
    return np.array(times), np.array(dt_de), np.array(dt_dh0), energy, d_energy


def zeno_time(e: float, h0: float, g: float = G) -> float:
    """The accumulation point t* of the bounces."""
    t1 = math.sqrt(2 * h0 / g)
    return t1 + 2 * e * math.sqrt(2 * g * h0) / (g * (1 - e)) if e < 1 else math.inf


@pytest.fixture(scope="module")
def ball_model():
    return hybc.Model.from_file(MODELS / "ball.hyb")


@pytest.fixture(scope="module")
def f(ball_model):
    return hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=4, t_end=T)


P0 = np.array([E, H0])


def test_closed_form_helper_matches_the_reference_numbers():
    times, _, dt_dh0, energy, (de, dh0) = ball_closed_form(E, H0, T)
    np.testing.assert_allclose(times, [0.4515236410, 1.1739614666, 1.7519117270, 2.2142719354], rtol=1e-10)
    assert dt_dh0[0] == pytest.approx(0.2257618205, rel=1e-9)
    assert (energy, de, dh0) == pytest.approx((1.6458448896, 16.458448896, 1.6458448896), rel=1e-9)


def test_values_event_times_and_status(f):
    out = f(jnp.array(P0))
    times, _, _, energy, _ = ball_closed_form(E, H0, T)
    assert set(out) == {"energy", "event_times", "n_events", "status"}
    assert out["energy"].shape == () and out["event_times"].shape == (4,)
    assert float(out["energy"]) == pytest.approx(energy, rel=VALUE_RTOL)
    np.testing.assert_allclose(out["event_times"], times, rtol=VALUE_RTOL)
    assert int(out["n_events"]) == 4
    assert hj.status_name(out["status"]) == "ok"


@pytest.mark.parametrize("jit", [False, True])
def test_grad_of_energy_against_closed_form(f, jit):
    grad = jax.grad(lambda p: f(p)["energy"])
    if jit:
        grad = jax.jit(grad)
    _, _, _, _, (de, dh0) = ball_closed_form(E, H0, T)
    np.testing.assert_allclose(grad(jnp.array(P0)), [de, dh0], rtol=GRAD_RTOL)


@pytest.mark.parametrize("jit", [False, True])
def test_jacfwd_of_event_times_against_closed_form(f, jit):
    jac = jax.jacfwd(lambda p: f(p)["event_times"])
    if jit:
        jac = jax.jit(jac)
    _, dt_de, dt_dh0, _, _ = ball_closed_form(E, H0, T)
    got = np.asarray(jac(jnp.array(P0)))
    assert got.shape == (4, 2)
    assert got[0, 1] == pytest.approx(0.2257618205, rel=GRAD_RTOL)  # dt1/dh0 = 1/sqrt(2 g h0)
    np.testing.assert_allclose(got[:, 0], dt_de, rtol=GRAD_RTOL, atol=1e-12)  # dt1/de = 0
    np.testing.assert_allclose(got[:, 1], dt_dh0, rtol=GRAD_RTOL)


@pytest.mark.parametrize("jit", [False, True])
def test_jacrev_equals_jacfwd(f, jit):
    def g(p):
        out = f(p)
        return jnp.concatenate([out["event_times"], out["energy"][None]])

    fwd, rev = jax.jacfwd(g), jax.jacrev(g)
    if jit:
        fwd, rev = jax.jit(fwd), jax.jit(rev)
    a, b = np.asarray(fwd(jnp.array(P0))), np.asarray(rev(jnp.array(P0)))
    assert a.shape == (5, 2)
    # Reverse mode by the adjoint (the plain run's steps) against the error-controlled forward
    # sensitivities: equal to the tolerances (test_jax_adjoint.py has the bounds).
    np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12)
    # With sens="forward" reverse mode transposes the forward Jacobians: both read the same
    # entries from one native call, through a one-hot product.
    fj = hj.function(f.model, params=["e", "h0"], outputs=["energy"], events=4, t_end=T, sens="forward")

    def gj(p):
        out = fj(p)
        return jnp.concatenate([out["event_times"], out["energy"][None]])

    p = jnp.array(P0)
    np.testing.assert_array_equal(np.asarray(jax.jacfwd(gj)(p)), np.asarray(jax.jacrev(gj)(p)))


@pytest.mark.parametrize("jit", [False, True])
def test_vmap_over_1000_restitutions(f, jit):
    """The issue's example range: below e ~ 0.69 the bounces accumulate before T = 2.5 (Zeno)."""
    es = np.linspace(0.65, 0.9, 1000)

    def energy_and_grad(e):
        def energy(e):
            out = f(jnp.stack([e, 1.0]))
            return out["energy"], (out["n_events"], out["status"])

        (value, (n_events, status)), de = jax.value_and_grad(energy, has_aux=True)(e)
        return value, de, n_events, status

    run = jax.vmap(energy_and_grad)
    if jit:
        run = jax.jit(run)
    energy, de, n_events, status = (np.asarray(a) for a in run(jnp.asarray(es)))
    zeno = status == hj.ZENO
    assert set(np.unique(status)) == {hj.OK, hj.ZENO}
    # Every point whose accumulation point comes before T is reported as Zeno, with NaN values.
    before = np.array([zeno_time(e, H0) < T for e in es])
    assert np.all(zeno[before]) and np.all(np.isnan(energy[zeno])) and np.all(np.isnan(de[zeno]))
    # Zeno is also reported where t* is just past T and the last bounces are below the tolerances
    # (heights under atol): a narrow band only.
    assert np.all([zeno_time(e, H0) < T + 0.05 for e in es[zeno]])
    ok = ~zeno
    assert ok.sum() > 800
    expected = [ball_closed_form(e, H0, T) for e in es[ok]]
    np.testing.assert_array_equal(n_events[ok], [len(c[0]) for c in expected])
    np.testing.assert_allclose(energy[ok], [c[3] for c in expected], rtol=VALUE_RTOL)
    np.testing.assert_allclose(de[ok], [c[4][0] for c in expected], rtol=GRAD_RTOL)


def test_vmap_nested_and_batched_jacobians(f):
    es = jnp.linspace(0.72, 0.85, 6)
    h0s = jnp.array([1.0, 1.5, 2.0])  # t* > T everywhere
    grid = jnp.stack(jnp.meshgrid(es, h0s, indexing="ij"), axis=-1)  # (6, 3, 2)
    jac = jax.vmap(jax.vmap(jax.jacfwd(lambda p: f(p)["event_times"])))(grid)
    assert jac.shape == (6, 3, 4, 2)
    for i, e in enumerate(np.asarray(es)):
        for j, h0 in enumerate(np.asarray(h0s)):
            times, dt_de, dt_dh0, _, _ = ball_closed_form(e, h0, T)
            k = min(len(times), 4)
            np.testing.assert_allclose(jac[i, j, :k, 0], dt_de[:k], rtol=GRAD_RTOL, atol=1e-12)
            np.testing.assert_allclose(jac[i, j, :k, 1], dt_dh0[:k], rtol=GRAD_RTOL)


def test_fit_restitution_with_grad_steps_in_fori_loop(f):
    """Fits e so that E(T) hits the energy of e* = 0.82 (four bounces before T at both)."""
    target = ball_closed_form(0.82, H0, T)[3]

    def loss(e):
        return (f(jnp.stack([e, 1.0]))["energy"] - target) ** 2

    step = jax.grad(loss)
    # loss'' = 2 (dE/de)^2 ~ 2 * 16.5^2 near e*, so a step of 1e-3 contracts the error by ~0.45.
    fit = jax.jit(lambda e0: jax.lax.fori_loop(0, 60, lambda _, e: e - 1e-3 * step(e), e0))
    e_fit = float(fit(jnp.float64(0.8)))
    assert e_fit == pytest.approx(0.82, abs=1e-9)


def test_tilted_floor_first_bounce_gradient_with_respect_to_slope():
    """dt1/ds = +0.1581 (the tutorial's library printed -0.0000)."""
    model = hybc.Model.from_file(MODELS / "tilted_ball.hyb")
    f = hj.function(model, params=["s"], events=1, t_end=0.6)
    g, s, vx0, h0 = 9.81, 0.1, 1.5, 1.0
    root = math.sqrt(s**2 * vx0**2 + 2 * g * h0)
    t1 = (s * vx0 + root) / g
    dt1_ds = (vx0 + s * vx0**2 / root) / g
    out = f(jnp.array([s]))
    assert float(out["event_times"][0]) == pytest.approx(t1, rel=VALUE_RTOL)
    grad = jax.jit(jax.grad(lambda p: f(p)["event_times"][0]))(jnp.array([s]))
    assert float(grad[0]) == pytest.approx(dt1_ds, rel=GRAD_RTOL)
    assert float(grad[0]) == pytest.approx(0.1581, abs=5e-5)


def test_unfired_slots_are_nan_with_zero_derivative(ball_model):
    f6 = hj.function(ball_model, params=["e", "h0"], outputs=["energy"], events=6, t_end=T)
    out = f6(jnp.array(P0))
    assert int(out["n_events"]) == 4
    assert np.all(np.isfinite(out["event_times"][:4]))
    assert np.all(np.isnan(out["event_times"][4:]))
    jac = np.asarray(jax.jacfwd(lambda p: f6(p)["event_times"])(jnp.array(P0)))
    np.testing.assert_array_equal(jac[4:], 0.0)
    # A loss over the fired slots only gets a finite gradient through the mask.
    masked = jax.grad(lambda p: jnp.nansum(f6(p)["event_times"]))(jnp.array(P0))
    assert np.all(np.isfinite(masked))


def test_more_events_than_slots_counts_them_all(ball_model):
    f2 = hj.function(ball_model, params=["e"], events=2, t_end=T)
    out = f2(jnp.array([E]))
    assert int(out["n_events"]) == 4 and out["event_times"].shape == (2,)
    np.testing.assert_allclose(out["event_times"], ball_closed_form(E, H0, T)[0][:2], rtol=VALUE_RTOL)


def test_zeno_is_reported_never_a_silent_number(ball_model):
    """Beyond the accumulation point t* = 4.0637 the ball stops early: status zeno, NaN energy."""
    fz = hj.function(ball_model, params=["e"], outputs=["energy"], events=3, t_end=5.0)
    out = jax.jit(fz)(jnp.array([E]))
    assert hj.status_name(out["status"]) == "zeno"
    assert math.isnan(float(out["energy"]))
    assert int(out["n_events"]) > 3
    np.testing.assert_allclose(out["event_times"], ball_closed_form(E, H0, 2.5)[0][:3], rtol=VALUE_RTOL)
    g = jax.grad(lambda p: fz(p)["energy"])(jnp.array([E]))
    assert math.isnan(float(g[0]))


CEILING = (MODELS.parent / "tests" / "data" / "run" / "ceiling_graze.hyb").read_text()


def test_grazing_is_reported_and_its_derivatives_are_nan():
    model = hybc.Model(CEILING, file_name="ceiling_graze.hyb")
    fg = hj.function(model, params=["H", "v0"], outputs=["y", "v"], events=1)
    out = fg(jnp.array([0.815494392476045, 4.0]))
    assert hj.status_name(out["status"]) == "grazing"
    assert int(out["n_events"]) == 1 and math.isfinite(float(out["event_times"][0]))
    jac = jax.jacfwd(lambda p: fg(p)["event_times"])(jnp.array([0.815494392476045, 4.0]))
    assert np.all(np.isnan(jac))


def test_out_of_range_parameter_is_bad_param_in_a_batch(f):
    out = jax.vmap(f)(jnp.array([[0.8, 1.0], [1.5, 1.0], [jnp.nan, 1.0]]))
    assert [hj.status_name(s) for s in out["status"]] == ["ok", "bad_param", "bad_param"]
    assert math.isfinite(float(out["energy"][0]))
    assert np.all(np.isnan(out["energy"][1:])) and np.all(np.isnan(out["event_times"][1:]))


def test_stop_event_values_carry_the_total_derivative():
    """y at a time-triggered stop at ts: y = h0 - g ts^2 / 2, dy/dts = -g ts, dy/dh0 = 1."""
    model = hybc.Model(
        "model s\nparam g = 9.81\nparam h0 = 10\nparam ts = 1\nstate y = h0\nstate v = 0\n"
        "der(y) = v\nder(v) = -g\nevent done when t >= ts {\n    stop\n}\n"
    )
    fs = hj.function(model, params=["ts", "h0"], outputs=["y"], events=1, t_end=5.0)
    p = jnp.array([1.2, 10.0])
    out = fs(p)
    assert float(out["y"]) == pytest.approx(10.0 - 9.81 * 1.2**2 / 2, rel=VALUE_RTOL)
    np.testing.assert_allclose(jax.grad(lambda p: fs(p)["y"])(p), [-9.81 * 1.2, 1.0], rtol=GRAD_RTOL)


def test_fixed_values_and_states_as_outputs(ball_model):
    fh = hj.function(ball_model, params=["e"], outputs=["y", "v"], events=1, values={"h0": 10.0}, t_end=2.0)
    out = fh(jnp.array([E]))
    # ../shared/reference/closed-forms.md, second point: x(2), v(2) at h0 = 10.
    assert float(out["y"]) == pytest.approx(4.80570772929, rel=VALUE_RTOL)
    assert float(out["v"]) == pytest.approx(5.59285386465, rel=VALUE_RTOL)
    dy = jax.jacfwd(lambda p: jnp.stack([fh(p)["y"], fh(p)["v"]]))(jnp.array([E]))
    np.testing.assert_allclose(dy[:, 0], [8.01428207183, 14.0071410359], rtol=GRAD_RTOL)


def test_float32_and_bad_shapes_are_refused(f):
    with pytest.raises(TypeError, match="jax_enable_x64"):
        f(jnp.array(P0, dtype=jnp.float32))
    with pytest.raises(ValueError, match="2 parameters"):
        f(jnp.array([0.8, 1.0, 3.0]))


def test_bad_names_raise_at_construction(ball_model):
    with pytest.raises(hybc.ParameterError, match="nope"):
        hj.function(ball_model, params=["nope"])
    with pytest.raises(ValueError, match="no output or state"):
        hj.function(ball_model, params=["e"], outputs=["power"])
    with pytest.raises(hybc.ParameterError):
        hj.function(ball_model, params=["e"], values={"e": 0.5})
    with pytest.raises(ValueError, match="t_end"):
        hj.function(ball_model, params=["e"], t_end=-1.0)
    with pytest.raises(ValueError, match="events: expected a non-negative integer"):
        hj.function(ball_model, params=["e"], events=2.5)
    with pytest.raises(ValueError, match="max_events: expected a non-negative integer"):
        hj.function(ball_model, params=["e"], max_events=-1)


def test_identical_functions_share_a_handle(ball_model):
    a = hj.function(ball_model, params=["e"], outputs=["energy"], events=2)
    b = hj.function(ball_model, params=["e"], outputs=["energy"], events=2)
    c = hj.function(ball_model, params=["e"], outputs=["energy"], events=3)
    assert a.handle == b.handle != c.handle


def test_second_derivatives_raise_instead_of_giving_zeros(f):
    """Sensitivities are first order: a derivative of the Jacobian is refused, not taken as 0."""
    with pytest.raises(ValueError, match="cannot be differentiated"):
        jax.hessian(lambda p: f(p)["energy"])(jnp.array(P0))


def test_malformed_raw_calls_get_named_errors(f):
    """The handler checks what XLA hands it; a call not made by hybc.jax gets a clear error."""
    shapes = (
        jax.ShapeDtypeStruct((1,), jnp.float64),
        jax.ShapeDtypeStruct((4,), jnp.float64),
        jax.ShapeDtypeStruct((), jnp.int32),
        jax.ShapeDtypeStruct((), jnp.int32),
    )
    call = jax.ffi.ffi_call("hybc_run", shapes)
    handle = np.int64(f.handle)
    cases = [
        (jnp.array(P0), {"handle": np.int64(10**9)}, "no function with handle"),
        (jnp.array(P0, dtype=jnp.float32), {"handle": handle}, "jax_enable_x64"),
        (jnp.array([0.8, 1.0, 2.0]), {"handle": handle}, r"takes 2 inputs \(e, h0\)"),
        (jnp.array(P0), {}, "no `handle` attribute"),
    ]
    for p, attrs, message in cases:
        with pytest.raises(Exception, match=message):
            jax.block_until_ready(call(p, **attrs))
    wrong_shape = jax.ffi.ffi_call("hybc_run", (jax.ShapeDtypeStruct((3,), jnp.float64),) + shapes[1:])
    with pytest.raises(Exception, match=r"values has shape \[3\], expected \[1\]"):
        jax.block_until_ready(wrong_shape(jnp.array(P0), handle=handle))


def test_not_differentiable_status_keeps_the_derivatives_that_exist():
    """x' = sqrt(|x|) from x0 = p = 0: dx/dp does not exist (NaN); y = exp(p t) has dy/dp = t."""
    model = hybc.Model(
        "model root\nparam p = 0\nstate x = p\nstate y = 1\nder(x) = sqrt(abs(x))\nder(y) = p * y\n"
    )
    fr = hj.function(model, params=["p"], outputs=["x", "y"], t_end=1.0)
    # The status describes the plain run that gives the values, in every mode: it computes no
    # derivatives, so it cannot say not_differentiable (Model.simulate(grad=) does).
    assert hj.status_name(fr(jnp.array([0.0]))["status"]) == "ok"
    out, _ = jax.jvp(fr, (jnp.array([0.0]),), (jnp.array([1.0]),))
    assert hj.status_name(out["status"]) == "ok"
    assert float(out["x"]) == 0.0 and float(out["y"]) == pytest.approx(1.0, rel=VALUE_RTOL)
    jac = jax.jacfwd(lambda p: jnp.stack([fr(p)["x"], fr(p)["y"]]))(jnp.array([0.0]))
    assert math.isnan(float(jac[0, 0]))
    assert float(jac[1, 0]) == pytest.approx(1.0, rel=GRAD_RTOL)
    # Reverse mode: the adjoint's pull-back of x is not finite, so the handler asks the forward
    # Jacobians, where it does not exist either (NaN); the derivative of y exists (by the adjoint
    # or, were its answer not finite, by the forward Jacobians).
    before = fr.counts()["transposed"]
    assert math.isnan(float(jax.grad(lambda p: fr(p)["x"])(jnp.array([0.0]))[0]))
    assert fr.counts()["transposed"] == before + 1
    assert float(jax.grad(lambda p: fr(p)["y"])(jnp.array([0.0]))[0]) == pytest.approx(1.0, rel=GRAD_RTOL)


def test_serial_and_parallel_batches_agree_bit_for_bit(f):
    """Batches of up to 4 points run on the calling thread, larger ones on the pool."""
    pts = jnp.stack([jnp.linspace(0.7, 0.9, 12), jnp.linspace(0.8, 1.4, 12)], axis=-1)
    whole = jax.jit(jax.vmap(jax.jacfwd(lambda p: f(p)["event_times"])))(pts)
    for i in range(0, 12, 3):
        part = jax.jit(jax.vmap(jax.jacfwd(lambda p: f(p)["event_times"])))(pts[i : i + 3])
        np.testing.assert_array_equal(part, whole[i : i + 3])
    single = [f(p)["energy"] for p in pts]
    np.testing.assert_array_equal(single, jax.vmap(f)(pts)["energy"])


def test_max_events_and_fault_are_reported(ball_model):
    capped = hj.function(ball_model, params=["e"], outputs=["energy"], events=4, max_events=3)
    out = capped(jnp.array([E]))
    assert hj.status_name(out["status"]) == "max_events" and int(out["n_events"]) == 3
    assert math.isnan(float(out["energy"])) and math.isnan(float(out["event_times"][3]))
    # x' = x^2 from x = k = 1 blows up at t = 1: the run fails before t_end = 2.
    model = hybc.Model("model blowup\nparam k = 1\nstate x = k\nder(x) = x^2\n")
    fb = hj.function(model, params=["k"], outputs=["x"], t_end=2.0)
    out = fb(jnp.array([1.0]))
    assert hj.status_name(out["status"]) == "fault" and math.isnan(float(out["x"]))
    # x' = k sqrt(x) + 1 from x = a = 0: the values run, but the error of dx/da (d sqrt/dx is
    # infinite at 0) cannot be met: the run with sensitivities fails, and its derivatives are NaN
    # (the values and the status are the plain run's, in every mode).
    model = hybc.Model("model nd\nparam a = 0\nparam k = 1\nstate x = a\nder(x) = k * sqrt(x) + 1\n")
    fs = hj.function(model, params=["a", "k"], outputs=["x"], t_end=1.0)
    p = jnp.array([0.0, 1.0])
    assert hj.status_name(fs(p)["status"]) == "ok"
    out, dx = jax.jvp(fs, (p,), (jnp.array([1.0, 0.0]),))
    assert hj.status_name(out["status"]) == "ok" and float(out["x"]) == float(fs(p)["x"])
    assert math.isnan(float(dx["x"]))
    assert np.all(np.isnan(jax.grad(lambda p: fs(p)["x"])(p)))


def test_event_slots_have_the_cli_cap(ball_model):
    # events=10**9 used to allocate gigabytes of slots; the cap is hybc sweep's --events (1000).
    with pytest.raises(ValueError, match="events: at most 1000, found 1000000000"):
        hj.function(ball_model, params=["e"], outputs=["energy"], events=10**9)
    with pytest.raises(ValueError, match="max_events: at least 1, found 0"):
        hj.function(ball_model, params=["e"], outputs=["energy"], max_events=0)
    with pytest.raises(TypeError, match=r"values: `h0`: expected a number"):
        hj.function(ball_model, params=["e"], outputs=["energy"], values={"h0": "1.0"})
    assert hj.function(ball_model, params=["e"], outputs=["energy"], events=1000).events == 1000


def test_one_status_vocabulary_with_model_simulate():
    # The same grazing run: hybc.jax's status name is Model.simulate's Run.status.
    model = hybc.Model(CEILING, file_name="ceiling_graze.hyb")
    p = [0.815494392476045, 4.0]
    out = hj.function(model, params=["H", "v0"], outputs=["y"], events=1)(jnp.array(p))
    run = model.simulate({"H": p[0], "v0": p[1]}, grad=["H", "v0"])
    assert hj.status_name(out["status"]) == run.status == "grazing"
    assert set(hj.STATUS.values()) - {"bad_param"} == {
        "ok", "grazing", "not_differentiable", "non_finite", "zeno", "stuck", "max_events", "fault"
    }


def ball_between_bounces(t: float, e: float = E, h0: float = H0):
    """y(t) and (dy/de, dy/dh0) over the first two flights (before the second bounce)."""
    t1 = math.sqrt(2 * h0 / G)
    if t <= t1:
        return h0 - 0.5 * G * t * t, (0.0, 1.0)
    tau = t - t1
    dt1 = 1.0 / (G * t1)
    y = e * G * t1 * tau - 0.5 * G * tau * tau
    return y, (G * t1 * tau, e * G * dt1 * tau - e * G * t1 * dt1 + G * tau * dt1)


def test_values_at_times_and_their_jvps_match_the_ball_between_bounces(ball_model):
    # 12 times over the first two flights (the second bounce is at 1.174): values and the
    # Jacobian of every sample against the closed form, and jax.grad of a trajectory loss.
    at = np.linspace(0.0, 1.15, 12)
    f = hj.function(ball_model, params=["e", "h0"], outputs=["y", "energy"], at=at, t_end=1.15)
    out = f(jnp.array(P0))
    assert out["samples"]["y"].shape == (12,)
    want = [ball_between_bounces(t) for t in at]
    np.testing.assert_allclose(out["samples"]["y"], [y for y, _ in want], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["samples"]["energy"], G * H0 * np.where(at < 0.4516, 1.0, E**2), rtol=1e-8)
    jac = jax.jacfwd(lambda p: f(p)["samples"]["y"])(jnp.array(P0))
    np.testing.assert_allclose(jac, [d for _, d in want], rtol=0, atol=1e-8)
    # A least-squares loss over the trajectory: its gradient is 2 sum (y - d) dy/dp.
    data = np.array([y for y, _ in want]) + 0.01
    loss = lambda p: jnp.sum((f(p)["samples"]["y"] - data) ** 2)  # noqa: E731
    g = jax.grad(loss)(jnp.array(P0))
    np.testing.assert_allclose(g, 2 * (-0.01) * np.sum([d for _, d in want], axis=0), rtol=1e-6)
    # The final value is still there, equal to the last sample's (both at t = 1.15).
    assert float(out["y"]) == pytest.approx(float(out["samples"]["y"][-1]), abs=1e-9)


def test_a_time_after_a_stop_reads_nan_and_too_many_samples_are_refused(ball_model):
    text = "model halt\nparam a = 1\nstate x = 0\nder(x) = a\nevent halt when t >= 0.5 {\n    stop\n}\n"
    f = hj.function(hybc.Model(text), params=["a"], outputs=["x"], at=[0.25, 0.75], t_end=1.0)
    s = f(jnp.array([2.0]))["samples"]["x"]
    assert float(s[0]) == pytest.approx(0.5, abs=1e-12) and math.isnan(float(s[1]))
    with pytest.raises(ValueError, match="numbers per point"):
        # 3 columns at 900,001 instants with 3 inputs: 1.08e7 numbers (80 MB) per point.
        hj.function(ball_model, params=["e", "h0", "g"], outputs=["y", "v", "energy"], at=np.linspace(0, 1, 900_000))


PWL_MODEL = """model ramp
param u[5] = 0 in [-10, 10]
param c = 1
state x = 0
der(x) = c * pwl(t, 0, 1, u)
"""


def test_a_vector_parameter_is_one_array_input():
    # x(1) = c * trapezoid(u) on 5 knots (spacing 1/4): weights (1, 2, 2, 2, 1) / 8.
    model = hybc.Model(PWL_MODEL)
    f = hj.function(model, params=["u", "c"], outputs=["x"], t_end=1.0)
    assert f.params == ["u[0]", "u[1]", "u[2]", "u[3]", "u[4]", "c"]
    u = jnp.array([0.5, -1.0, 2.0, 3.0, -0.25])
    weights = np.array([1, 2, 2, 2, 1]) / 8
    x = float(f({"u": u, "c": 2.0})["x"])
    assert x == pytest.approx(2.0 * float(weights @ u), rel=1e-12)
    g = jax.grad(lambda p: f(p)["x"])({"u": u, "c": 2.0})
    np.testing.assert_allclose(g["u"], 2.0 * weights, rtol=1e-10)
    assert float(g["c"]) == pytest.approx(float(weights @ u), rel=1e-10)
    # The flat vector is the same input.
    flat = jax.grad(lambda p: f(p)["x"])(jnp.concatenate([u, jnp.array([2.0])]))
    np.testing.assert_allclose(flat[:5], g["u"], rtol=0, atol=0)
    with pytest.raises(ValueError, match=r"input `u` is a vector of 5, got shape \(3,\)"):
        f({"u": jnp.zeros(3), "c": 1.0})
    with pytest.raises(ValueError, match="expected the inputs"):
        f({"u": u})
    # A vector parameter that is not an input takes an array in values=.
    h = hj.function(model, params=["c"], outputs=["x"], values={"u": np.ones(5)}, t_end=1.0)
    assert float(h(jnp.array([3.0]))["x"]) == pytest.approx(3.0, rel=1e-12)
