"""hybc.Model and Model.simulate against closed forms; errors a user can make."""

import json
import math
import pickle

import numpy as np
import pytest

import hybc
from conftest import MODELS, REPO, ball_bounces, ball_energy

G = 9.81


def test_names_and_defaults(ball):
    assert ball.name == "ball"
    assert ball.params == {"g": 9.81, "e": 0.8, "h0": 1.0}
    assert list(ball.params) == ["g", "e", "h0"]
    assert ball.param_ranges == {"e": (0.0, 1.0)}
    assert ball.states == ["y", "v"]
    assert ball.outputs == ["energy"]
    assert ball.events == ["touchdown"]
    assert ball.file_name.endswith("ball.hyb")
    assert hybc.Model(ball.source).params == ball.params


def test_ball_event_times_and_energy_match_the_closed_form(ball):
    # The tutorial's numbers: g = 9.81, e = 0.8, h0 = 1, T = 2.5, four bounces.
    run = ball.simulate(grad=["e", "h0"])
    expected = ball_bounces(G, 0.8, 1.0, 2.5)
    assert len(expected) == 4
    np.testing.assert_allclose(run.event_times, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(expected, [0.4515236410, 1.1739614666, 1.7519117270, 2.2142719354], atol=1e-10)
    assert run.event_names == ["touchdown"] * 4
    assert run.stopped_by == "t_end" and run.status == "ok" and run.ok and run.error is None
    assert run.warnings == []
    assert run.t == 2.5 and run.t_end == 2.5
    energy, de, dh0 = ball_energy(G, 0.8, 1.0, 4)
    assert math.isclose(energy, 1.6458448896, rel_tol=1e-10)
    assert math.isclose(run.outputs["energy"], energy, rel_tol=1e-8)
    assert run.grad == ["e", "h0"]
    assert run.doutputs["energy"].shape == (2,)
    np.testing.assert_allclose(run.doutputs["energy"], [de, dh0], rtol=1e-7)
    assert set(run.state) == {"y", "v"} and set(run.dstate) == {"y", "v"}


def test_dt1_dh0_is_one_over_the_impact_speed(ball):
    run = ball.simulate({"e": 0.9}, grad=["e", "h0"], t_end=2.5, rtol=1e-10)
    assert run.event_dtime.shape == (len(run.event_times), 2)
    dt1_dh0 = 1 / math.sqrt(2 * G * 1.0)
    assert math.isclose(dt1_dh0, 0.2257618205, rel_tol=1e-9)
    assert math.isclose(run.event_dtime[0, 1], dt1_dh0, rel_tol=1e-8)
    assert run.event_dtime[0, 0] == 0.0  # the first impact does not depend on e
    # At e = 0.9 three bounces come before T = 2.5: E(T) = g h0 e^6.
    expected = ball_bounces(G, 0.9, 1.0, 2.5)
    np.testing.assert_allclose(run.event_times, expected, atol=1e-9)
    energy, de, dh0 = ball_energy(G, 0.9, 1.0, len(expected))
    assert math.isclose(run.outputs["energy"], energy, rel_tol=1e-8)
    np.testing.assert_allclose(run.doutputs["energy"], [de, dh0], rtol=1e-7)


def test_second_closed_form_point_with_every_gradient(ball):
    # closed-forms.md, g = 9.81, e = 0.8, h0 = 10, T = 2 (between bounces 1 and 2).
    run = ball.simulate({"h0": 10}, grad=["h0", "g", "e"], t_end=2)
    assert math.isclose(run.event_times[0], 1.42784312293, rel_tol=1e-9)
    np.testing.assert_allclose(run.event_dtime[0], [0.0713921561464, -0.0727748788444, 0], atol=1e-9)
    assert math.isclose(run.state["y"], 4.80570772929, rel_tol=1e-8)
    assert math.isclose(run.state["v"], 5.59285386465, rel_tol=1e-8)
    np.testing.assert_allclose(run.dstate["y"], [-0.0787146135354, 0.570117621269, 8.01428207183], rtol=1e-7)
    np.testing.assert_allclose(run.dstate["v"], [1.26064269323, -0.714941189366, 14.0071410359], rtol=1e-7)


def test_tilted_floor_first_bounce_slope_gradient():
    # t1 = (s vx0 + sqrt(s^2 vx0^2 + 2 g h0)) / g; the tutorial printed -0.0000 for dt1/ds.
    model = hybc.Model.from_file(MODELS / "tilted_ball.hyb")
    run = model.simulate(grad=["s"])
    s, vx0, h0 = 0.1, 1.5, 1.0
    root = math.sqrt(s**2 * vx0**2 + 2 * G * h0)
    t1 = (s * vx0 + root) / G
    dt1_ds = (vx0 + s * vx0**2 / root) / G
    assert math.isclose(run.event_times[0], t1, rel_tol=1e-9)
    assert round(dt1_ds, 4) == 0.1581
    assert math.isclose(run.event_dtime[0, 0], dt1_ds, rel_tol=1e-7)
    np.testing.assert_allclose(run.event_times, [0.4671, 1.1899, 1.7682, 2.2308, 2.6009, 2.8970], atol=6e-5)


def test_zeno_is_reported_never_a_silent_number(ball):
    run = ball.simulate(grad=["e"], t_end=10)
    t_star = 4.0637127689
    assert run.stopped_by == "zeno" and run.status == "zeno" and not run.ok
    assert "Zeno" in run.error and "4.06371276" in run.error
    assert run.t <= t_star + 1e-6
    # No final values exist at t_end = 10: NaN, not the state where the run stopped.
    assert all(math.isnan(v) for v in run.state.values())
    assert math.isnan(run.outputs["energy"]) and np.isnan(run.doutputs["energy"]).all()
    assert len(run.event_times) > 20 and (np.diff(run.event_times) > 0).all()


CEILING = (REPO / "tests/data/run/ceiling_graze.hyb").read_text()


def test_grazing_is_reported_with_nan_gradients():
    model = hybc.Model(CEILING)
    run = model.simulate(grad=["g", "v0", "H"])
    assert run.event_names[0] == "ceiling"
    assert any("grazes" in w for w in run.warnings), run.warnings
    assert np.isnan(run.event_dtime[0]).all()
    # The state after the contact depends on its time: no derivative exists.
    assert np.isnan(run.dstate["v"]).all()
    # The run itself ended as asked (ok), but its status says what became of the gradients, in
    # the word hybc.jax and the sweep rows use for the same run (issue 24: it used to say "ok").
    assert run.ok and run.status == "grazing"
    table = model.sweep({"v0": [4.0]}, grad=["v0"], events=1)
    assert table["status"].tolist() == ["grazing"]


def test_a_bad_model_raises_model_error_with_a_caret(tmp_path):
    text = "model m\nparam a = 1\nstate x = 0\nder(x) = a * y\n"
    with pytest.raises(hybc.ModelError) as info:
        hybc.Model(text)
    message = str(info.value)
    assert "model.hyb:4:14" in message and "unknown name `y`" in message
    assert "der(x) = a * y" in message
    lines = message.splitlines()
    source_line = next(line for line in lines if line.endswith("der(x) = a * y"))
    caret_line = next(line for line in lines if "^" in line)
    assert caret_line.index("^") == source_line.rindex("y")  # the caret points at the `y`
    path = tmp_path / "bad.hyb"
    path.write_text(text)
    with pytest.raises(hybc.ModelError, match=rf"{path}:4:14"):
        hybc.Model.from_file(path)
    with pytest.raises(hybc.ModelError, match="my.hyb:4:14"):
        hybc.Model(text, file_name="my.hyb")
    assert issubclass(hybc.ModelError, ValueError)


def test_a_missing_file_is_an_os_error(tmp_path):
    with pytest.raises(OSError, match="cannot read"):
        hybc.Model.from_file(tmp_path / "nope.hyb")


def test_bad_parameters_and_options_are_refused(ball):
    with pytest.raises(hybc.ParameterError, match=r"no parameter `ee`.*did you mean `e`"):
        ball.simulate({"ee": 0.5})
    with pytest.raises(hybc.ParameterError, match=r"e = 1.5 is outside its range \[0, 1\]"):
        ball.simulate({"e": 1.5})
    with pytest.raises(hybc.ParameterError, match="not a finite number"):
        ball.simulate({"h0": float("nan")})
    with pytest.raises(hybc.ParameterError, match="no parameter `k`"):
        ball.simulate(grad=["k"])
    with pytest.raises(hybc.ParameterError, match="named twice"):
        ball.simulate(grad=["e", "e"])
    with pytest.raises(ValueError, match="rtol: expected a positive number, found -1"):
        ball.simulate(rtol=-1)
    with pytest.raises(ValueError, match="rtol: expected a number below 1"):
        ball.simulate(rtol=2)
    with pytest.raises(ValueError, match="t_end"):
        ball.simulate(t_end=float("inf"))
    with pytest.raises(ValueError, match="method"):
        ball.simulate(method="euler")
    with pytest.raises(ValueError, match="trajectory"):
        ball.simulate(trajectory="every")
    with pytest.raises(ValueError, match="trajectory"):
        ball.simulate(trajectory=-0.1)
    with pytest.raises(ValueError, match="max_events: expected a non-negative integer, found -3"):
        ball.simulate(max_events=-3)
    with pytest.raises(TypeError):
        ball.simulate(rtoll=1e-6)
    assert issubclass(hybc.ParameterError, ValueError)


def test_sampled_trajectory_matches_the_piecewise_parabola(ball):
    run = ball.simulate(trajectory=0.1)
    traj = run.trajectory
    np.testing.assert_allclose(traj["t"], np.arange(26) * 0.1, atol=1e-12)
    bounces = ball_bounces(G, 0.8, 1.0, 2.5)
    v1 = math.sqrt(2 * G)
    for t, y in zip(traj["t"], traj["y"]):
        k = int(np.searchsorted(bounces, t))  # bounces before t
        if k == 0:
            expect = 1.0 - G * t**2 / 2
        else:
            dt = t - bounces[k - 1]
            expect = 0.8**k * v1 * dt - G * dt**2 / 2
        assert abs(y - expect) < 1e-8, (t, y, expect)
    assert list(traj["mode"]) == ["main"] * 26 or len(set(traj["mode"])) == 1
    assert ball.simulate().trajectory is None


def test_steps_trajectory_has_both_sides_of_every_event(ball):
    run = ball.simulate(grad=["e"], trajectory="steps")
    traj = run.trajectory
    t = traj["t"]
    assert t[0] == 0 and t[-1] == 2.5 and (np.diff(t) >= 0).all()
    for te in run.event_times:
        at = np.flatnonzero(t == te)
        assert len(at) == 2, te  # before and after the reset
        v_before, v_after = traj["v"][at]
        assert math.isclose(v_after, -0.8 * v_before, rel_tol=1e-12)
    assert "dy/de" in traj and len(traj["dv/de"]) == len(t)


def test_models_pickle_as_their_text(ball):
    again = pickle.loads(pickle.dumps(ball))
    assert again.source == ball.source and again.file_name == ball.file_name
    assert again.simulate().event_times.tolist() == ball.simulate().event_times.tolist()


def test_to_json_is_the_cli_report(ball):
    import json

    report = json.loads(ball.simulate({"e": 0.9}, grad=["e"]).to_json())
    assert report["model"] == "ball" and len(report["events"]) == 3


def test_a_stop_event_gives_values_at_the_stop_and_total_derivatives():
    # Stopped at t = ts: y = h0 - g ts^2 / 2, so dy/dts = -g ts (the motion of the stopping time
    # included) and dy/dh0 = 1.
    text = (
        "model s\nparam g = 9.81\nparam h0 = 10\nparam ts = 1\nstate y = h0\nstate v = 0\n"
        "der(y) = v\nder(v) = -g\nevent done when t >= ts {\n    stop\n}\n"
    )
    run = hybc.Model(text).simulate(grad=["ts", "h0"], t_end=5, rtol=1e-10, atol=1e-12)
    assert run.stopped_by == "done" and run.status == "ok" and run.ok
    assert math.isclose(run.t, 1.0, rel_tol=1e-12) and run.t_end == 5
    assert math.isclose(run.state["y"], 10 - G / 2, rel_tol=1e-10)
    np.testing.assert_allclose(run.dstate["y"], [-G, 1.0], rtol=1e-8)
    np.testing.assert_allclose(run.dstate["v"], [-G, 0.0], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(run.event_dtime, [[1.0, 0.0]], atol=1e-12)


# ---- issue 24, item 13: bad input gets a clear message ----


def test_grad_must_be_a_sequence_of_names_not_a_string(ball):
    # list("h0") would be the parameters `h` and `0`: a string is refused, naming the fix.
    with pytest.raises(TypeError, match=r"grad: expected a sequence of parameter names such as \['h0'\], found the string 'h0'"):
        ball.simulate(grad="h0")
    with pytest.raises(TypeError, match="grad: expected a sequence of parameter names"):
        ball.sweep({"e": [0.5]}, grad="e")
    with pytest.raises(TypeError, match="grad: expected parameter names"):
        ball.simulate(grad=[1])
    # A one-name sequence is what it looks like.
    run = ball.simulate(grad=("h0",))
    assert run.grad == ["h0"] and run.dstate["y"].shape == (1,)


def test_parameter_values_must_be_numbers(ball):
    with pytest.raises(TypeError, match=r"params: `e`: expected a number, found str '0.9'"):
        ball.simulate({"e": "0.9"})
    with pytest.raises(TypeError, match=r"params: `e`: expected a number, found bool True"):
        ball.simulate({"e": True})
    with pytest.raises(TypeError, match=r"points: `h0`: expected numbers"):
        ball.sweep({"e": [0.5], "h0": "1.0"})
    with pytest.raises(TypeError, match=r"points: `e`: expected numbers"):
        ball.sweep({"e": ["0.5"]})
    with pytest.raises(TypeError, match=r"fixed: `h0`: expected a number"):
        hybc.Samples(4, fixed={"h0": "2"})
    # Python and NumPy numbers of any kind are numbers.
    assert ball.simulate({"e": np.float32(0.5), "h0": 2}).params["h0"] == 2.0


def test_counts_have_the_cli_caps(ball):
    # The caps are hybc::limits, the CLI's (docs/cli.md, Limits); 0 events would still fire one.
    with pytest.raises(ValueError, match="max_events: at least 1, found 0"):
        ball.simulate(max_events=0)
    with pytest.raises(ValueError, match="max_events: at most 1000000, found 1000001"):
        ball.simulate(max_events=10**6 + 1)
    with pytest.raises(ValueError, match="events: at most 1000, found 1001"):
        ball.sweep({"e": [0.5]}, events=1001)
    with pytest.raises(ValueError, match="threads: at most 1024, found 1025"):
        ball.sweep({"e": [0.5]}, threads=1025)
    run = ball.simulate(max_events=1)
    assert run.status == "max_events" and len(run.event_times) == 1


VECTOR_MODEL = """model dot
param u[5] = 0 in [-5, 5]
param w[5] = 1
state x = 0
der(x) = dot(u, w)
output s = sum(u)
"""


def test_a_vector_parameter_takes_an_array():
    # der(x) = dot(u, w): x(T) = T sum u_k w_k, dx/du_k = T w_k, exactly.
    model = hybc.Model(VECTOR_MODEL)
    assert model.vectors == [("u", 5), ("w", 5)]
    assert list(model.params)[:6] == ["u[0]", "u[1]", "u[2]", "u[3]", "u[4]", "w[0]"]
    u = np.array([0.5, -1.0, 2.0, 3.0, -0.25])
    w = np.arange(1.0, 6.0)
    run = model.simulate({"u": u, "w": w}, grad=["u", "w[4]"], t_end=2.0)
    assert math.isclose(run.state["x"], 2.0 * float(u @ w), rel_tol=1e-12)
    assert math.isclose(run.outputs["s"], float(u.sum()), rel_tol=1e-12)
    np.testing.assert_allclose(run.dstate["x"], list(2.0 * w) + [2.0 * u[4]], rtol=1e-12)
    one = model.simulate({"u[3]": 1.0}, t_end=1.0)
    assert math.isclose(one.state["x"], 1.0, rel_tol=1e-12)


def test_a_vector_parameter_refuses_a_wrong_shape_or_range():
    model = hybc.Model(VECTOR_MODEL)
    with pytest.raises(ValueError, match=r"`u` is a vector of 5 parameters: expected a 1-D array of 5 values, found shape \(3,\)"):
        model.simulate({"u": np.zeros(3)})
    with pytest.raises(TypeError, match="expected numbers"):
        model.simulate({"u": ["a"] * 5})
    with pytest.raises(hybc.ParameterError, match=r"u\[2\] = 9 is outside its range"):
        model.simulate({"u": [0, 0, 9, 0, 0]})


def test_values_at_times_match_the_ball_between_bounces(ball):
    # The first flight: y = h0 - g t^2 / 2, dy/dh0 = 1, dy/de = 0; the second: after t1 the ball
    # leaves at e g t1, y = e g t1 tau - g tau^2 / 2 with tau = t - t1, dy/de = g t1 tau.
    t1 = math.sqrt(2.0 / G)
    at = np.linspace(0.0, 1.15, 24)
    run = ball.simulate(grad=["e", "h0"], at=at, t_end=1.15)
    s = run.samples
    assert s["names"] == ["energy", "y", "v"]
    assert s["values"].shape == (24, 3) and s["dvalues"].shape == (24, 3, 2)
    np.testing.assert_array_equal(s["t"], at)
    for k, t in enumerate(at):
        if t <= t1:
            y, dy_de, dy_dh0 = 1.0 - 0.5 * G * t * t, 0.0, 1.0
        else:
            tau = t - t1
            y, dy_de = 0.8 * G * t1 * tau - 0.5 * G * tau * tau, G * t1 * tau
            dt1 = 1.0 / (G * t1)
            dy_dh0 = 0.8 * G * dt1 * tau - 0.8 * G * t1 * dt1 + G * tau * dt1
        assert s["values"][k, 1] == pytest.approx(y, abs=1e-9)
        assert s["dvalues"][k, 1, 0] == pytest.approx(dy_de, abs=1e-8)
        assert s["dvalues"][k, 1, 1] == pytest.approx(dy_dh0, abs=1e-8)
    assert s["reached"].all() if isinstance(s["reached"], np.ndarray) else all(s["reached"])
    assert (s["near_event"] == -1).all()
    assert ball.simulate().samples is None
    with pytest.raises(Exception, match="at: the times must ascend, but 0.2 comes after 0.5"):
        ball.simulate(at=[0.5, 0.2])
    with pytest.raises(Exception, match="at: time 3 is after t_end = 2.5"):
        ball.simulate(at=[3.0])


def test_simulation_keywords_are_one_set_with_one_check(ball):
    # One parser reads the simulation keywords of every entry point: an unknown keyword names the
    # known ones, a wrong type names the keyword, and quadrature_error_control reaches the run.
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'rtoll' \(the simulation keywords are t_end, rtol"):
        ball.simulate(rtoll=1e-6)
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'rtoll'"):
        ball.sweep({"e": [0.5, 0.6]}, rtoll=1e-6)
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'rtoll'"):
        ball.optimize(["e"], "energy", rtoll=1e-6)
    with pytest.raises(TypeError, match=r"method: expected"):
        ball.simulate(method=5)
    # A running cost its steps resolve, out of the step-size norm (the default) and in it: the
    # steps of the model without the cost (12), and more (14 measured by `hybc run` with and
    # without `--quadrature-error-control`). The shipped models' costs take the same steps either
    # way since a cost's own error rejects the steps that leave it inaccurate.
    decay = "model decay\nparam k = 1\nstate x = 1\nder(x) = -k * x\nsimulate t_end = 5, rtol = 1e-8, atol = 1e-10\n"
    costed = hybc.Model(decay.replace("der(x) = -k * x\n", "der(x) = -k * x\nstate cost = 0\nder(cost) = x^2\n"))
    steps = lambda run: json.loads(run.to_json())["stats"]["steps"]  # noqa: E731
    on, off = costed.simulate(quadrature_error_control=True), costed.simulate()
    assert steps(off) == steps(costed.simulate(quadrature_error_control=False)) == steps(hybc.Model(decay).simulate())
    assert steps(off) < steps(on)
    assert off.state["cost"] == pytest.approx(on.state["cost"], rel=1e-6)


def test_t_start_is_the_clis_flag_and_times_stay_absolute():
    # `hybc run tests/data/cli/run_t_start_late/model.hyb --t-start 1e6 --t-end 1000001 --grad all`:
    # the dose at the absolute time 1e6 + 0.5, x(T) = (e^-0.25 + 1) e^-0.25, dx/dt_dose = k e^-0.25.
    late = hybc.Model.from_file(REPO / "tests/data/cli/run_t_start_late/model.hyb")
    run = late.simulate(grad=["t_dose"], t_start=1e6, t_end=1e6 + 1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(run.event_times, [1e6 + 0.5], rtol=0, atol=1e-9)
    assert run.state["x"] == pytest.approx((math.exp(-0.25) + 1) * math.exp(-0.25), rel=1e-8)
    assert run.dstate["x"][0] == pytest.approx(0.5 * math.exp(-0.25), rel=1e-7)
    # The same checks and words as the CLI's (`--t-start 5` on the ball: after its end time).
    with pytest.raises(ValueError, match=r"t_end: expected a time after t_start = 5, found 2.5 \(the model's end time\)"):
        hybc.Model.from_file(MODELS / "ball.hyb").simulate(t_start=5)
    with pytest.raises(ValueError, match="t_start: expected a finite number"):
        late.simulate(t_start=float("nan"))


def test_land_events_is_the_clis_flag(ball):
    # `hybc run models/ball.hyb --grad e --land-events`: the same events and bounce times to the
    # tolerances, one more step attempt per bounce (more right-hand-side evaluations, same steps).
    rhs = lambda run: json.loads(run.to_json())["stats"]["rhs_calls"]  # noqa: E731
    plain, landed = ball.simulate(grad=["e"]), ball.simulate(grad=["e"], land_events=True)
    assert len(landed.event_times) == len(plain.event_times) > 0
    np.testing.assert_allclose(landed.event_times, plain.event_times, rtol=1e-9)
    assert rhs(landed) > rhs(plain)
