"""Element names of arrays, loops and event families (issue #41) through ``hybc.jax``: a function
takes a vector parameter whole (``h``, ``m``) or by element and returns states by element
(``y[1]``) and event times by element and firing (``floor[0]#2``, ``hit[6]#1``), with
``jax.grad`` (the adjoint) and ``jax.jacfwd`` (forward sensitivities) against closed forms and
against ``Model.simulate``'s gradients of the same names.

``tests/data/run/drops.hyb`` drops ball ``i`` from ``h_i (i + 1)`` onto a floor that halves its
speed: its first floor event is at ``t1 = sqrt(2 h_i (i + 1) / g)``, the second at ``2 t1``, and
``dt1/dh_i = t1 / (2 h_i)``. ``models/box.hyb`` at speed scale ``s``: every event time is ``t / s``
(``dt/ds = -t`` at 1), a position at the end ``x(t_end) = x(s t_end; 1)`` (``dx/ds = t_end v``),
``ke = s^2 ke(1)`` and ``d ke/dm_k = v_k^2 / 2``.

Tolerances: the closed forms at 1e-7 relative (as test_jax.py: sensitivities under the error
control); ``jax.jacfwd`` against ``Model.simulate`` with the same options at 1e-12 (one
computation); ``jax.grad`` by the adjoint (the plain run's steps) against either at 1e-7.
"""

from __future__ import annotations

import math
import os

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
from conftest import MODELS, REPO  # noqa: E402

G = 9.81
GRAD_RTOL = 1e-7
H = np.array([1.0, 1.0, 1.3])


@pytest.fixture(scope="module")
def drops():
    return hybc.Model.from_file(REPO / "tests" / "data" / "run" / "drops.hyb")


@pytest.fixture(scope="module")
def box():
    return hybc.Model.from_file(MODELS / "box.hyb")


def t1(h, i):
    return math.sqrt(2 * h * (i + 1) / G)


DROPS_OUT = ["y[1]", "v[0]", "floor[2]#1", "floor[0]#2", "floor[1]#last", "floor[2]#3"]


def drops_closed_form(h):
    """The values of DROPS_OUT at t_end = 1 and their derivatives by h (3 columns)."""
    values, jac = [], np.zeros((len(DROPS_OUT), 3))
    # y[1]: one bounce at a = t1(h1, 1), then up at g a / 2: y = g/2 (a (t - a) - (t - a)^2).
    a, t = t1(h[1], 1), 1.0
    values.append(G / 2 * (a * (t - a) - (t - a) ** 2))
    jac[0, 1] = G / 2 * (3 * (t - a) - a) * a / (2 * h[1])
    # v[0]: two bounces (at b and 2 b), leaving the second at g b / 4, then falling to t = 1.
    b = t1(h[0], 0)
    values.append(G * b / 4 - G * (t - 2 * b))
    jac[1, 0] = 2.25 * G * b / (2 * h[0])
    # floor[2]#1 and floor[0]#2; floor[1]#last is its only firing; floor[2]#3 never fires.
    c = t1(h[2], 2)
    values += [c, 2 * b, a, math.nan]
    jac[2, 2] = c / (2 * h[2])
    jac[3, 0] = b / h[0]
    jac[4, 1] = a / (2 * h[1])
    return np.array(values), jac


def test_element_names_in_and_out(drops):
    f = hj.function(drops, params=["h"], outputs=DROPS_OUT, t_end=1.0)
    assert f.params == ["h[0]", "h[1]", "h[2]"]
    out = f({"h": jnp.asarray(H)})
    assert set(out) == set(DROPS_OUT) | {"event_times", "n_events", "status"}
    want, _ = drops_closed_form(H)
    got = np.array([float(out[name]) for name in DROPS_OUT])
    np.testing.assert_allclose(got[:5], want[:5], rtol=1e-9)
    assert math.isnan(got[5])  # floor[2] fired once before t_end: no third firing
    # The flat vector of the same inputs, in the order of f.params, gives the same numbers.
    flat = f(jnp.asarray(H))
    np.testing.assert_array_equal([float(flat[n]) for n in DROPS_OUT], got)


@pytest.mark.parametrize("jit", [False, True])
def test_grad_and_jacfwd_by_element_name_match_closed_forms_and_simulate(drops, jit):
    f = hj.function(drops, params=["h"], outputs=DROPS_OUT, t_end=1.0)
    _, want = drops_closed_form(H)

    def column(p):
        out = f(p)
        return jnp.stack([out[name] for name in DROPS_OUT[:5]])

    fwd = jax.jacfwd(column)
    if jit:
        fwd = jax.jit(fwd)
    got_fwd = np.asarray(fwd(jnp.asarray(H)))
    np.testing.assert_allclose(got_fwd, want[:5], rtol=GRAD_RTOL, atol=1e-12)
    # The unfired firing is a pad: derivative 0, as an unfired slot's.
    pad = jax.grad(lambda p: f(p)["floor[2]#3"])(jnp.asarray(H))
    np.testing.assert_array_equal(pad, np.zeros(3))

    # Model.simulate with the same names and options: the same forward sensitivities.
    run = drops.simulate({"h": H}, grad=["h"], t_end=1.0)
    assert run.grad == f.params
    firings: dict[str, list[int]] = {}
    for k, name in enumerate(run.event_names):
        firings.setdefault(name, []).append(k)
    rows = {
        "y[1]": run.dstate["y[1]"],
        "v[0]": run.dstate["v[0]"],
        "floor[2]#1": run.event_dtime[firings["floor[2]"][0]],
        "floor[0]#2": run.event_dtime[firings["floor[0]"][1]],
        "floor[1]#last": run.event_dtime[firings["floor[1]"][-1]],
    }
    for i, name in enumerate(DROPS_OUT[:5]):
        np.testing.assert_allclose(got_fwd[i], rows[name], rtol=1e-12, atol=1e-15, err_msg=name)
        # Reverse mode, each name's own gradient, as a dict of the whole vector parameter.
        grad = jax.grad(lambda p, name=name: f(p)[name])
        if jit:
            grad = jax.jit(grad)
        g = grad({"h": jnp.asarray(H)})
        assert set(g) == {"h"} and g["h"].shape == (3,)
        np.testing.assert_allclose(g["h"], rows[name], rtol=GRAD_RTOL, atol=1e-12, err_msg=name)
    assert f.counts()["adjoint"] > 0  # the reverse pulls went through the adjoint


def test_box_families_and_a_whole_mass_vector(box):
    outputs = ["ke", "x[2]", "hit[6]#1", "high[7]#1", "hit[5]#1", "low[0]#1"]
    f = hj.function(box, params=["s", "m"], outputs=outputs, events=3, t_end=0.6)
    assert f.params == ["s"] + [f"m[{k}]" for k in range(8)]
    p = {"s": jnp.asarray(1.0), "m": jnp.ones(8)}
    out = f(p)
    run = box.simulate(grad=["s", "m"], t_end=0.6)
    assert run.event_names[:3] == ["high[7]", "hit[6]", "hit[5]"]
    # The values come from the plain run (no sensitivities in its error test), the slots too.
    np.testing.assert_allclose(out["event_times"], run.event_times[:3], rtol=1e-9)
    for k, name in enumerate(["high[7]", "hit[6]", "hit[5]"]):
        assert float(out[f"{name}#1"]) == float(out["event_times"][k])
    assert "low[0]" not in run.event_names and math.isnan(float(out["low[0]#1"]))
    v = np.array([run.state[f"v[{k}]"] for k in range(8)])
    ke = float(out["ke"])
    assert ke == pytest.approx(run.outputs["ke"], rel=1e-12)

    # ke = s^2 ke(1), d ke/d m[k] = v_k^2 / 2: reverse mode returns the dict's shape.
    g = jax.grad(lambda q: f(q)["ke"])(p)
    assert g["s"].shape == () and g["m"].shape == (8,)
    assert float(g["s"]) == pytest.approx(2 * ke, rel=1e-9)
    np.testing.assert_allclose(g["m"], v**2 / 2, rtol=1e-9)
    # dt/ds = -t for each named firing; dx[2]/ds = t_end v[2]; neither moves with the masses.
    for name in ["hit[6]#1", "high[7]#1", "hit[5]#1"]:
        for mode in (jax.grad, jax.jacfwd):
            d = mode(lambda q, name=name: f(q)[name])(p)
            assert float(d["s"]) == pytest.approx(-float(out[name]), rel=1e-8), (name, mode)
            np.testing.assert_array_equal(d["m"], np.zeros(8))
    d = jax.jacfwd(lambda q: f(q)["x[2]"])(p)
    assert float(d["s"]) == pytest.approx(0.6 * v[2], rel=1e-8)
    np.testing.assert_allclose(float(d["s"]), run.dstate["x[2]"][0], rtol=1e-12)


def test_bad_event_names_are_refused_by_name(box):
    with pytest.raises(ValueError, match=r"hit\[9\]"):
        hj.function(box, params=["s"], outputs=["hit[9]#1"], t_end=0.6)
    with pytest.raises(ValueError, match=r"hit\[2\]#0"):
        hj.function(box, params=["s"], outputs=["hit[2]#0"], t_end=0.6)
    with pytest.raises(ValueError, match=r"at="):
        hj.function(box, params=["s"], outputs=["hit[2]#1"], t_end=0.6, at=[0.1, 0.2])
    with pytest.raises(ValueError, match=r"x\[8\]"):
        hj.function(box, params=["s"], outputs=["x[8]"], t_end=0.6)
