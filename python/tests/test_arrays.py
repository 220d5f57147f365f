"""Element names of arrays, loops and event families (issue #41) through the Python package:
``tests/data/run/drops.hyb`` drops ball ``i`` from ``h[i] (i + 1)`` (a state array whose initial
values are a vector parameter), so its first floor event is at ``sqrt(2 h_i (i + 1) / g)`` with
``dt/dh_i = t / (2 h_i)``, and ``y[i](t) = h_i (i + 1) - g t^2 / 2`` before it."""

import math

import numpy as np
import pytest

import hybc
from conftest import MODELS, REPO

G = 9.81


@pytest.fixture
def drops():
    return hybc.Model.from_file(REPO / "tests" / "data" / "run" / "drops.hyb")


def first_floor(h, i):
    return math.sqrt(2 * h * (i + 1) / G)


def test_names_are_the_element_names(drops):
    assert drops.states == ["y[0]", "v[0]", "y[1]", "v[1]", "y[2]", "v[2]"]
    assert drops.events == ["floor[0]", "floor[1]", "floor[2]"]
    assert list(drops.params) == ["g", "h[0]", "h[1]", "h[2]"]


def test_set_an_element_and_grad_on_an_element(drops):
    run = drops.simulate({"h[1]": 2.0}, grad=["h[1]"])
    assert run.grad == ["h[1]"]
    h = [1.0, 2.0, 1.0]
    first = {}
    for name, t, dt in zip(run.event_names, run.event_times, run.event_dtime):
        first.setdefault(name, (t, dt))
    assert set(first) == {"floor[0]", "floor[1]", "floor[2]"}
    for i, hi in enumerate(h):
        t, dt = first[f"floor[{i}]"]
        assert math.isclose(t, first_floor(hi, i), rel_tol=0, abs_tol=1e-9)
        # Only h[1] is differentiated: ball 1's time moves with it, the others' do not.
        want = t / (2 * hi) if i == 1 else 0.0
        assert math.isclose(dt[0], want, rel_tol=1e-7, abs_tol=1e-12), (i, dt[0], want)


def test_a_vector_parameter_whole_in_params_and_grad(drops):
    h = np.array([1.2, 2.0, 0.5])
    run = drops.simulate({"h": h}, grad=["h"])
    assert run.grad == ["h[0]", "h[1]", "h[2]"]
    for i, hi in enumerate(h):
        k = run.event_names.index(f"floor[{i}]")
        t = run.event_times[k]
        assert math.isclose(t, first_floor(hi, i), rel_tol=0, abs_tol=1e-9)
        want = np.zeros(3)
        want[i] = t / (2 * hi)
        np.testing.assert_allclose(run.event_dtime[k], want, rtol=1e-7, atol=1e-12)


def test_of_a_whole_state_array_and_an_element_at_a_time(drops):
    full = drops.simulate(grad=["h"])
    some = drops.simulate(grad=["h"], of=["y"])
    assert set(some.dstate) == {"y[0]", "y[1]", "y[2]"}
    for name in some.dstate:
        np.testing.assert_array_equal(some.dstate[name], full.dstate[name])
    # Every element at a time: y[i](0.25) = h_i (i + 1) - g t^2 / 2 before its bounce, so
    # dy[i]/dh[j] = (i + 1) if i == j else 0.
    at = drops.simulate(grad=["h"], of=["y@0.25"])
    samples = at.samples
    np.testing.assert_array_equal(samples["t"], [0.25])
    for i in range(3):
        col = samples["names"].index(f"y[{i}]")
        assert math.isclose(samples["values"][0, col], (i + 1) - 0.5 * G * 0.0625, rel_tol=0, abs_tol=1e-9)
        want = np.zeros(3)
        want[i] = i + 1
        np.testing.assert_allclose(samples["dvalues"][0, col, :], want, rtol=0, atol=1e-9)


def test_the_box_event_families_through_python():
    model = hybc.Model.from_file(MODELS / "box.hyb")
    assert model.events[:2] == ["low[0]", "high[0]"] and model.events[-1] == "hit[6]"
    run = model.simulate(grad=["s"], t_end=0.6)
    # Scaling every speed by s scales every time by 1 / s: dt/ds = -t at s = 1.
    assert run.event_names[:3] == ["high[7]", "hit[6]", "hit[5]"]
    np.testing.assert_allclose(run.event_dtime[:, 0], -np.asarray(run.event_times), rtol=1e-8)
    # ke = s^2 ke(1): d ke/ds = 2 ke.
    assert math.isclose(run.doutputs["ke"][0], 2 * run.outputs["ke"], rel_tol=1e-9)
