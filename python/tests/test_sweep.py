"""Model.sweep: the columns of `hybc sweep`, closed forms over 1000 points, any memory order."""

import csv
import io
import math
import os
import pathlib
import subprocess

import numpy as np
import pytest

import hybc
from conftest import MODELS, REPO, ball_bounces, ball_energy

G = 9.81


def test_a_thousand_restitutions_against_the_closed_form(ball):
    e = np.linspace(0.65, 0.9, 1000)
    table = ball.sweep({"e": e}, grad=["e"], events=5)
    assert len(table["e"]) == 1000 and (table["e"] == e).all()
    # Below e = 0.694 the bounces accumulate before T = 2.5 (t* = t1 + 2 e v1 / (g (1 - e))):
    # those points are Zeno rows, never a number at T.
    v1 = math.sqrt(2 * G)
    t_star = math.sqrt(2 / G) + 2 * e * v1 / (G * (1 - e))
    zeno = table["status"] == "zeno"
    assert set(table["status"]) == {"ok", "zeno"}
    assert zeno[t_star < 2.5 - 1e-3].all() and not zeno[t_star > 2.5 + 1e-2].any()
    assert (table["error"][~zeno] == "").all()
    assert all("Zeno" in m for m in table["error"][zeno])
    assert np.isnan(table["energy"][zeno]).all() and np.isnan(table["denergy/de"][zeno]).all()
    for i, ei in enumerate(e):
        bounces = ball_bounces(G, ei, 1.0, min(2.5, t_star[i]))
        k = len(bounces)
        if not zeno[i]:
            assert table["events"][i] == k
        for slot in range(5):
            t = table[f"t{slot + 1}"][i]
            if slot < k:
                assert abs(t - bounces[slot]) < 1e-9, (ei, slot)
                assert table[f"event{slot + 1}"][i] == "touchdown"
            else:
                assert math.isnan(t) and table[f"event{slot + 1}"][i] == ""
        if not zeno[i]:
            energy, de, _ = ball_energy(G, ei, 1.0, k)
            assert math.isclose(table["energy"][i], energy, rel_tol=1e-8), (ei, k)
            assert math.isclose(table["denergy/de"][i], de, rel_tol=1e-6), (ei, k)
    # dt1/de = 0 and dt2/de = 2 v1 / g (flight 1 lasts 2 e v1 / g).
    assert (table["dt1/de"] == 0).all()
    np.testing.assert_allclose(table["dt2/de"], 2 * v1 / G, rtol=1e-7)


def test_columns_and_dtypes(ball):
    table = ball.sweep({"e": [0.7, 0.8]}, grad=["e", "h0"], events=2)
    expect = ["g", "e", "h0", "status", "events", "event1", "t1", "dt1/de", "dt1/dh0",
              "event2", "t2", "dt2/de", "dt2/dh0", "t_final", "y", "v", "energy",
              "dy/de", "dv/de", "dy/dh0", "dv/dh0", "denergy/de", "denergy/dh0", "error"]
    assert list(table) == expect
    assert table["events"].dtype == np.int64
    assert table["status"].dtype.kind == "U" and table["event1"].dtype.kind == "U"
    assert table["t1"].dtype == np.float64


def test_rows_equal_single_runs_bit_for_bit(ball):
    e = np.array([0.66, 0.75, 0.83])
    h0 = np.array([0.5, 1.0, 2.0])
    table = ball.sweep({"e": e, "h0": h0, "g": 9.0}, grad=["h0"], events=3)
    assert (table["g"] == 9.0).all()
    for i in range(3):
        run = ball.simulate({"e": e[i], "h0": h0[i], "g": 9.0}, grad=["h0"])
        n = min(3, len(run.event_times))
        assert table["t1"][i] == run.event_times[0]
        assert (table["dt1/dh0"][i] == run.event_dtime[0, 0])
        assert [table[f"t{k + 1}"][i] for k in range(n)] == run.event_times[:n].tolist()
        assert table["status"][i] == run.status
        # NaN (no value at T after a Zeno stop) compares equal here.
        np.testing.assert_array_equal([table["y"][i], table["dv/dh0"][i]], [run.state["y"], run.dstate["v"][0]])
    assert table["status"].tolist() == ["zeno", "ok", "ok"]


def test_fortran_ordered_strided_and_unaligned_points_give_the_right_rows(ball):
    rows = np.array([[0.66, 0.5], [0.75, 1.0], [0.83, 2.0], [0.9, 1.5]])
    reference = ball.sweep(rows, names=["e", "h0"], events=2)
    fortran = np.asfortranarray(rows)
    assert not fortran.flags.c_contiguous
    as_arrays = [fortran, np.ascontiguousarray(rows.T).T, rows[::-1][::-1]]
    as_dicts = [
        {"e": fortran[:, 0], "h0": fortran[:, 1]},  # contiguous columns of a Fortran array
        {"e": rows[:, 0], "h0": rows[:, 1]},  # strided columns of a C array
        {"e": list(rows[:, 0]), "h0": tuple(rows[:, 1])},  # plain sequences
    ]
    tables = [ball.sweep(p, names=["e", "h0"], events=2) for p in as_arrays]
    tables += [ball.sweep(p, events=2) for p in as_dicts]
    for table in tables:
        for name in reference:
            np.testing.assert_array_equal(table[name], reference[name], err_msg=name)
    np.testing.assert_array_equal(reference["e"], rows[:, 0])
    np.testing.assert_array_equal(reference["h0"], rows[:, 1])
    # A non-contiguous slice: every other point of a longer sweep.
    long = np.linspace(0.65, 0.9, 21)
    sliced = ball.sweep({"e": long[::2]}, events=3)
    copied = ball.sweep({"e": np.ascontiguousarray(long[::2])}, events=3)
    for name in copied:
        np.testing.assert_array_equal(sliced[name], copied[name], err_msg=name)
    np.testing.assert_array_equal(sliced["e"], long[::2])
    # An unaligned buffer (float64 at an odd address).
    raw = bytearray(8 * 4 + 1)
    raw[1:] = rows[:, 0].tobytes()
    unaligned = np.frombuffer(raw, dtype=np.float64, count=4, offset=1)
    assert not unaligned.flags.aligned
    table = ball.sweep({"e": unaligned, "h0": rows[:, 1]}, events=2)
    for name in reference:
        np.testing.assert_array_equal(table[name], reference[name], err_msg=name)


def test_threads_do_not_change_a_bit(ball):
    e = np.linspace(0.65, 0.9, 200)
    one = ball.sweep({"e": e}, grad=["e"], threads=1)
    many = ball.sweep({"e": e}, grad=["e"], threads=4)
    for name in one:
        np.testing.assert_array_equal(one[name], many[name], err_msg=name)


def test_grid_order_is_that_of_hybc_sweep():
    points = hybc.grid(e=[0.7, 0.8], h0=[1.0, 2.0, 3.0])
    assert points["e"].tolist() == [0.7, 0.7, 0.7, 0.8, 0.8, 0.8]
    assert points["h0"].tolist() == [1.0, 2.0, 3.0] * 2


def test_bad_points_are_refused(ball):
    with pytest.raises(hybc.ParameterError, match=r"e = 1.2 \(point 1\) is outside its range \[0, 1\]"):
        ball.sweep({"e": [0.5, 1.2]})
    with pytest.raises(hybc.ParameterError, match="not a finite number"):
        ball.sweep({"h0": [1.0, np.inf]})
    with pytest.raises(hybc.ParameterError, match="no parameter `q`"):
        ball.sweep({"q": [1.0]})
    with pytest.raises(ValueError, match="differ in length"):
        ball.sweep({"e": [0.5, 0.6], "h0": [1.0]})
    with pytest.raises(ValueError, match="scalar or a 1-D array"):
        ball.sweep({"e": np.ones((2, 2)) * 0.5})
    with pytest.raises(TypeError, match="names="):
        ball.sweep(np.ones((2, 2)))
    with pytest.raises(ValueError, match="2 columns for 1 names"):
        ball.sweep(np.ones((2, 2)) * 0.5, names=["e"])
    with pytest.raises(ValueError, match="no 1-D array to vary"):
        ball.sweep({"e": 0.5})
    with pytest.raises(ValueError, match="events: expected a non-negative integer, found -1"):
        ball.sweep({"e": [0.5]}, events=-1)
    with pytest.raises(ValueError, match="threads: expected a non-negative integer, found 1.5"):
        ball.sweep({"e": [0.5]}, threads=1.5)
    assert all(len(v) == 0 for v in ball.sweep({"e": []}).values())
    with pytest.raises(ValueError, match="events: at most"):
        ball.sweep({"e": [0.5]}, events=10**6)
    with pytest.raises(TypeError, match="expected numbers"):
        ball.sweep({"e": ["a", "b"]})


def test_runs_that_end_early_are_rows_with_a_status(ball):
    table = ball.sweep({"e": [0.5, 0.8]}, t_end=10, events=1)
    assert table["status"].tolist() == ["zeno", "zeno"]
    assert all("Zeno" in m for m in table["error"])
    assert np.isnan(table["energy"]).all()


def hybc_binary():
    """The `hybc` command of this checkout (built by `cargo build`; .ci/run builds it first)."""
    for profile in ("debug", "release"):
        path = REPO / "target" / profile / "hybc"
        if path.exists():
            return path
    if os.environ.get("HYBC_CI"):
        raise AssertionError("target/*/hybc is missing: .ci/run builds it before pytest")
    pytest.skip("no target/*/hybc (run `cargo build` to compare with the CLI)")


def test_the_same_table_as_hybc_sweep(ball):
    header, rows = cli_table([MODELS / "ball.hyb", "--vary", "e=0.3,0.65,0.8,0.95", "--grad", "e,h0",
                              "--events", "6", "--t-end", "5"])
    table = ball.sweep({"e": [0.3, 0.65, 0.8, 0.95]}, grad=["e", "h0"], events=6, t_end=5)
    assert set(table["status"]) == {"ok", "zeno"}
    assert_same_as_cli(table, header, rows)


def cli_table(args):
    """`hybc sweep ARGS` read back as header and rows of text."""
    out = subprocess.run([hybc_binary(), "sweep", *args], capture_output=True, text=True)
    assert out.returncode in (0, 3), out.stderr  # 3: some points ended early (Zeno)
    rows = list(csv.reader(io.StringIO(out.stdout)))
    return rows[0], rows[1:]


def assert_same_as_cli(table, header, rows):
    assert list(table) == header
    assert all(len(v) == len(rows) for v in table.values())
    for i, row in enumerate(rows):
        for name, cell in zip(header, row):
            value = table[name][i]
            if table[name].dtype.kind == "U":
                assert value == cell, (name, i)
            elif cell == "":
                assert math.isnan(value), (name, i)
            else:
                assert value == float(cell), (name, i, value, cell)  # bit for bit


def test_samples_are_those_of_hybc_sweep_samples(ball):
    header, rows = cli_table([MODELS / "ball.hyb", "--samples", "50", "--seed", "3", "--vary", "e",
                              "--vary", "h0=0.5:2", "--set", "g=9.5", "--grad", "e", "--events", "3"])
    samples = hybc.Samples(50, seed=3, ranges={"e": None, "h0": (0.5, 2)}, fixed={"g": 9.5})
    table = ball.sweep(samples, grad=["e"], events=3)
    assert_same_as_cli(table, header, rows)
    points = samples.points(ball)
    assert list(points) == ["e", "h0"] and (points["e"] == table["e"]).all()
    # Without ranges: every parameter that declares one (e only), as --samples without --vary.
    header, rows = cli_table([MODELS / "ball.hyb", "--samples", "20"])
    assert_same_as_cli(ball.sweep(hybc.Samples(20)), header, rows)


def test_bad_samples_are_refused(ball):
    with pytest.raises(hybc.ParameterError, match="outside its declared range"):
        ball.sweep(hybc.Samples(5, ranges={"e": (0.5, 1.5)}))
    with pytest.raises(hybc.ParameterError, match="no declared range"):
        ball.sweep(hybc.Samples(5, ranges={"h0": None}))
    with pytest.raises(hybc.ParameterError, match="lo < hi"):
        ball.sweep(hybc.Samples(5, ranges={"h0": (2, 1)}))
    with pytest.raises(ValueError, match="expected 1 to"):
        ball.sweep(hybc.Samples(0))
    with pytest.raises(hybc.ParameterError, match="both"):
        ball.sweep(hybc.Samples(5, fixed={"e": 0.5}))


def test_the_gil_is_released_while_a_sweep_runs(ball):
    # A sweep of a few tenths of a second in a thread; this thread keeps running Python meanwhile.
    # Were the GIL held, no iteration here could run until the sweep returned.
    import threading
    import time

    e = np.linspace(0.7, 0.9, 20000)
    done = threading.Event()
    result = {}

    def work():
        result["table"] = ball.sweep({"e": e}, threads=1)
        done.set()

    started = time.perf_counter()
    worker = threading.Thread(target=work)
    worker.start()
    ticks = 0
    while not done.is_set():
        ticks += 1
        time.sleep(0.001)
    worker.join()
    elapsed = time.perf_counter() - started
    assert len(result["table"]["e"]) == 20000
    assert elapsed > 0.05, "the sweep was too short to tell"
    assert ticks >= 10, (ticks, elapsed)


def test_a_vector_parameter_is_varied_by_rows_or_fixed_by_one_array():
    # der(x) = dot(u, w) to T = 2: x = 2 u.w, dx/du_k = 2 w_k.
    text = "model dot\nparam u[3] = 0 in [-5, 5]\nparam w[3] = 1\nstate x = 0\nder(x) = dot(u, w)\n"
    model = hybc.Model(text)
    rows = np.array([[1.0, 2.0, 3.0], [0.5, -1.0, 0.0]])
    w = np.array([1.0, 10.0, 100.0])
    out = model.sweep({"u": rows, "w": w}, grad=["u"], t_end=2.0)
    np.testing.assert_allclose(out["x"], 2 * rows @ w, rtol=1e-12)
    np.testing.assert_allclose(out["dx/du[1]"], [20.0, 20.0], rtol=1e-12)
    with pytest.raises(ValueError, match=r"`u` is a vector of 3 parameters"):
        model.sweep({"u": np.zeros((2, 4))})
