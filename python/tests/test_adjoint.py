"""Model.simulate(sens="adjoint"): the gradients by the discrete adjoint (hybc run --sens) equal
the forward sensitivities of the run that takes the same steps (sens_error_control=False) to
1e-10 relative, and the run says which mode computed them (run.sens, run.stats, the JSON)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import hybc

TOL = 1e-10

# The ball under a force control of 50 knots.
CONTROLLED = """model controlled
param g = 9.81
param e = 0.8 in [0, 1]
param h0 = 1.0
param u[50] = 0
state y = h0
state v = 0
der(y) = v
der(v) = -g + pwl(t, 0, 2.5, u)
event touchdown when y <= 0 {
    v := -e * v
}
output energy = 0.5 * v^2 + g * y
simulate t_end = 2.5, rtol = 1e-10, atol = 1e-12
"""


def rel_close(a, b, rtol=TOL):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    scale = max(float(np.max(np.abs(b))), 1e-300)
    assert np.max(np.abs(a - b)) <= rtol * scale, (np.max(np.abs(a - b)) / scale, a, b)


def same_gradients(adjoint, forward):
    assert adjoint.grad == forward.grad
    assert len(adjoint.event_times) == len(forward.event_times) > 0
    np.testing.assert_array_equal(adjoint.event_times, forward.event_times)
    rel_close(adjoint.event_dtime, forward.event_dtime)
    for name in forward.dstate:
        rel_close(adjoint.dstate[name], forward.dstate[name])
    for name in forward.doutputs:
        rel_close(adjoint.doutputs[name], forward.doutputs[name])


def test_adjoint_equals_forward_on_the_ball(ball):
    grad = ["e", "h0", "g"]
    adjoint = ball.simulate(grad=grad, sens="adjoint")
    forward = ball.simulate(grad=grad, sens_error_control=False)
    same_gradients(adjoint, forward)
    assert adjoint.sens == "adjoint" and adjoint.stats["sens"] == "adjoint"
    assert forward.sens == "forward" and forward.stats["sens"] == "forward"
    assert json.loads(adjoint.to_json())["stats"]["sens"] == "adjoint"
    # The closed form through the 4 bounces before t = 2.5: E = g h0 e^8.
    assert adjoint.doutputs["energy"][0] == pytest.approx(8 * 9.81 * 0.8**7, rel=1e-7)


def test_adjoint_equals_forward_under_a_50_knot_control():
    model = hybc.Model(CONTROLLED)
    u = 0.8 * np.sin(np.linspace(0, 6 * np.pi, 50))
    adjoint = model.simulate({"u": u}, grad=["u", "e"], sens="adjoint")
    forward = model.simulate({"u": u}, grad=["u", "e"], sens_error_control=False)
    assert len(adjoint.grad) == 51
    same_gradients(adjoint, forward)
    assert adjoint.sens == "adjoint" and forward.sens == "forward"
    assert np.count_nonzero(adjoint.doutputs["energy"][:50]) > 25


def test_stats_without_gradients_and_auto(ball):
    plain = ball.simulate()
    assert plain.sens is None and plain.stats["sens"] is None
    assert plain.stats["steps"] > 0 and plain.stats["events"] == len(plain.event_times)
    # auto: 7 quantities (4 event times, 2 states, 1 output) against 1 parameter: forward.
    assert ball.simulate(grad=["e"], sens="auto").sens == "forward"


def test_a_bad_mode_names_the_three(ball):
    with pytest.raises(ValueError, match=r'sens: expected "forward", "adjoint" or "auto", found "backward"'):
        ball.simulate(grad=["e"], sens="backward")


def test_of_keeps_only_the_gradients_asked_for_in_either_mode():
    # `of=` (hybc run --of): the dicts hold the names asked for, the event gradients not asked
    # for are NaN, the values are untouched; the adjoint's rows equal the full run's.
    model = hybc.Model(CONTROLLED)
    grad = ["e", "h0", "u"]
    for sens in ("forward", "adjoint"):
        full = model.simulate(grad=grad, sens=sens, sens_error_control=False)
        some = model.simulate(grad=grad, sens=sens, sens_error_control=False, of=["v", "touchdown#2"])
        assert some.sens == sens
        assert list(some.dstate) == ["v"] and list(some.doutputs) == []
        rel_close(some.dstate["v"], full.dstate["v"])
        np.testing.assert_array_equal(some.event_times, full.event_times)
        rel_close(some.event_dtime[1], full.event_dtime[1])
        assert np.isnan(some.event_dtime[0]).all() and np.isnan(some.event_dtime[2:]).all()
        assert some.state == full.state


def test_of_names_that_are_not_quantities_are_refused():
    model = hybc.Model(CONTROLLED)
    with pytest.raises(ValueError, match="of: model has no output or state `w`"):
        model.simulate(grad=["e"], of=["w"])
    with pytest.raises(TypeError, match="of: expected a sequence of quantity names"):
        model.simulate(grad=["e"], of="v")
