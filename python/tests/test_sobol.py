"""Model.sobol and Model.sobol_design: the numbers of `hybc sobol` (same design, same
estimators), the Ishigami function's analytic indices, the rows without a value that the ball's
closed form predicts, and SALib's problem dict refused clearly where hybc has no such prior."""

import csv
import json
import math
import subprocess

import numpy as np
import pytest

import hybc
from conftest import MODELS, REPO, ball_bounces
from test_sweep import hybc_binary

ISHIGAMI = REPO / "tests" / "data" / "sobol" / "ishigami.hyb"
BALL_PROBLEM = {"names": ["h0", "e", "g"], "bounds": [[0.5, 1.5], [0.75, 0.9], [9.0, 10.5]]}


def cli_sobol(args):
    out = subprocess.run([hybc_binary(), "sobol", *map(str, args), "--format", "json"],
                         capture_output=True, text=True)
    assert out.returncode in (0, 3), out.stderr
    return json.loads(out.stdout)


def test_the_same_indices_as_hybc_sobol(ball):
    # T = 5: the rows with a low e reach their accumulation point first (Zeno), so the counts and
    # the drop policy are exercised as well as the indices.
    cli = cli_sobol([MODELS / "ball.hyb", "--vary", "h0=0.5:1.5", "--vary", "e=0.75:0.9",
                     "--vary", "g=9:10.5", "--output", "energy,touchdown#last", "-n", "256",
                     "--seed", "4", "--second-order", "--on-fail", "drop", "--t-end", "5"])
    res = ball.sobol(BALL_PROBLEM, ["energy", "touchdown#last"], 256, seed=4, second_order=True,
                     on_fail="drop", t_end=5)
    assert res.names == cli["parameters"] and res.runs == cli["runs"] == 256 * 8
    assert res.ended_early == cli["ended_early"] and res.ended_early["zeno"] > 0
    assert res.first_ended_early_row == cli["first_ended_early_row"]
    for out in cli["outputs"]:
        mine = res[out["name"]]
        assert mine["on_fail"] == "drop"
        for key in ("failed_rows", "dropped_base_points", "base_points", "variance"):
            assert mine[key] == out[key], key
        for key in ("S1", "ST", "S1_conf", "ST_conf"):
            np.testing.assert_array_equal(mine[key], out[key], err_msg=key)
        for key in ("S2", "S2_conf"):  # JSON's null is NaN here, as in SALib
            cli_matrix = np.array([[math.nan if v is None else v for v in row] for row in out[key]])
            np.testing.assert_array_equal(mine[key], cli_matrix, err_msg=key)
    assert res["energy"]["failed_rows"] == np.isnan(res["energy"]["Y"]).sum() > 0


@pytest.mark.parametrize("dist, bounds, flag", [
    ("unif", [0.5, 1.5], "h0=0.5:1.5"),
    ("logunif", [0.1, 10], "h0=loguniform:0.1:10"),
    ("norm", [1.0, 0.1], "h0=normal:1:0.1"),
    ("lognorm", [0.0, 0.2], "h0=lognormal:0:0.2"),
])
def test_salib_distribution_names_are_the_cli_priors(ball, dist, bounds, flag, tmp_path):
    problem = {"names": ["h0", "e"], "bounds": [bounds, [0.6, 0.9]], "dists": [dist, "unif"]}
    rows = ball.sobol_design(problem, 16, seed=9, second_order=True)
    assert rows.shape == (16 * 6, 2)
    path = tmp_path / "design.csv"
    cli_sobol([MODELS / "ball.hyb", "--vary", flag, "--vary", "e=0.6:0.9", "--output", "energy",
               "-n", "16", "--seed", "9", "--second-order", "--bootstrap", "0", "--design-out", path])
    with open(path) as f:
        lines = list(csv.reader(f))
    assert lines[0] == ["h0", "e"]
    np.testing.assert_array_equal(rows, np.array(lines[1:], dtype=float))


def test_design_rows_are_blocks_in_salib_order(ball):
    rows = ball.sobol_design(BALL_PROBLEM, 8, seed=2, second_order=True)
    d = 3
    assert rows.shape == (8 * (2 * d + 2), d)
    for b in range(8):
        block = rows[b * 8:(b + 1) * 8]
        a, bb = block[0], block[-1]
        for i in range(d):
            ab = a.copy()
            ab[i] = bb[i]
            ba = bb.copy()
            ba[i] = a[i]
            np.testing.assert_array_equal(block[1 + i], ab)
            np.testing.assert_array_equal(block[1 + d + i], ba)
    lo, hi = np.array(BALL_PROBLEM["bounds"]).T
    assert ((rows > lo) & (rows < hi)).all()
    # Without second order the blocks are A, AB_1 .. AB_D, B, and the base points the same.
    first = ball.sobol_design(BALL_PROBLEM, 8, seed=2)
    np.testing.assert_array_equal(first[0::5], rows[0::8])
    np.testing.assert_array_equal(first[4::5], rows[7::8])


def ishigami_indices():
    a, b, pi4 = 7.0, 0.1, math.pi ** 4
    v1 = 0.5 + b * pi4 / 5 + b * b * pi4 * pi4 / 50
    v2 = a * a / 8
    v13 = b * b * pi4 * pi4 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return np.array([v1, v2, 0]) / v, np.array([v1 + v13, v2, v13]) / v


def test_ishigami_gives_the_analytic_indices_within_three_standard_errors():
    model = hybc.Model.from_file(ISHIGAMI)
    problem = {"names": ["x1", "x2", "x3"], "bounds": [[-math.pi, math.pi]] * 3}
    # Seed 28 and N = 2^14, fixed before looking (the Rust test's, tests/it/sobol.rs).
    res = model.sobol(problem, ["f"], 1 << 14, seed=28, bootstrap=300)["f"]
    s1, st = ishigami_indices()
    np.testing.assert_allclose([s1[0], st[2]], [0.3139, 0.2437], atol=1e-4)
    for key, exact in (("S1", s1), ("ST", st)):
        se = res[f"{key}_conf"] / 1.959963984540054
        assert (se < 0.02).all(), (key, se)  # small enough for the check to mean something
        assert (np.abs(res[key] - exact) <= 3 * se).all(), (key, res[key], exact, se)
    assert (res["failed_rows"], res["base_points"]) == (0, 1 << 14)


def test_rows_without_a_third_touchdown_are_the_closed_forms(ball):
    # At T = 1.6 the third touchdown, t1 (1 + 2 e + 2 e^2), fires for some rows only.
    t_end = 1.6
    rows = ball.sobol_design(BALL_PROBLEM, 64, seed=0)
    missing = np.array([len(ball_bounces(g, e, h0, t_end)) < 3 for h0, e, g in rows])
    assert 0 < missing.sum() < len(rows)
    with pytest.raises(hybc.SobolError, match=f"{missing.sum()} of 320 rows have no value") as info:
        ball.sobol(BALL_PROBLEM, ["touchdown#3", "energy"], 64, seed=0, t_end=t_end)
    refused = info.value.result
    assert set(refused["touchdown#3"]) == {"error", "Y"}
    np.testing.assert_array_equal(np.isnan(refused["touchdown#3"]["Y"]), missing)
    assert refused["energy"]["failed_rows"] == 0  # the other output is analysed
    blocks = missing.reshape(64, 5).any(axis=1)
    drop = ball.sobol(BALL_PROBLEM, ["touchdown#3"], 64, seed=0, t_end=t_end, on_fail="drop")
    r = drop["touchdown#3"]
    assert (r["failed_rows"], r["dropped_base_points"], r["base_points"]) == (
        missing.sum(), blocks.sum(), 64 - blocks.sum())
    assert drop.ended_early == {} and drop.first_ended_early_row is None
    value = ball.sobol(BALL_PROBLEM, ["touchdown#3"], 64, seed=0, t_end=t_end, on_fail="value=1.6")
    assert value["touchdown#3"]["failed_rows"] == missing.sum()
    assert value["touchdown#3"]["base_points"] == 64 and value["touchdown#3"]["on_fail"] == "value=1.6"


def test_the_tutorial_s_zeno_rows_are_those_the_closed_form_predicts(ball):
    # docs/tutorial.md, section 7: the rows whose accumulation time t* = t1 (1 + 2 e / (1 - e))
    # comes before T = 2.5 end by Zeno, and no other (the closest t* is 9e-5 from T).
    problem = {"names": ["h0", "e", "g"], "bounds": [[0.5, 1.5], [0.6, 0.9], [9, 10.5]]}
    h0, e, g = ball.sobol_design(problem, 2048, seed=1).T
    t_star = np.sqrt(2 * h0 / g) * (1 + 2 * e / (1 - e))
    res = ball.sobol(problem, ["energy"], 2048, seed=1, on_fail="value=0")
    assert res.ended_early == {"zeno": 3318} == {"zeno": (t_star < 2.5).sum()}
    np.testing.assert_array_equal(np.isnan(res["energy"]["Y"]), t_star < 2.5)


def test_runs_that_end_early_are_counted(ball):
    res = ball.sobol(BALL_PROBLEM, ["energy"], 32, seed=3, t_end=5, on_fail="drop")
    assert set(res.ended_early) == {"zeno"}
    y = res["energy"]["Y"]
    assert res.ended_early["zeno"] == np.isnan(y).sum()
    assert res.first_ended_early_row == np.flatnonzero(np.isnan(y))[0] + 1


def test_bad_problems_and_arguments_are_refused_clearly(ball):
    one = lambda **kw: {"names": ["e"], "bounds": [[0.6, 0.9]], **kw}  # noqa: E731
    cases = [
        (one(dists=["triang"]), hybc.ParameterError, 'dists\\[0\\] = "triang" for `e`: hybc\'s priors'),
        (one(dists=["truncnorm"]), hybc.ParameterError, "\"unif\", \"logunif\", \"norm\" and \"lognorm\""),
        (one(bounds=[[0.9, 0.6]]), hybc.ParameterError, "lower bound must be below the upper"),
        (one(bounds=[[0.5, 1.2]]), hybc.ParameterError, "outside `e`'s declared range \\[0, 1\\]"),
        (one(dists=["norm"], bounds=[[0.8, 0.05]]), hybc.ParameterError, "the prior reaches \\[-inf, inf\\]"),
        ({"names": ["h0"], "bounds": [[0.0, 1.0]], "dists": ["logunif"]}, hybc.ParameterError,
         "log-uniform range must be positive"),
        ({"names": ["h0"], "bounds": [[1.0, 0.0]], "dists": ["lognorm"]}, hybc.ParameterError,
         "standard deviation must be positive"),
        ({"names": ["h0"], "bounds": [[1.0, 2.0, 3.0]]}, hybc.ParameterError, "expected 2 numbers"),
        ({"names": ["hO"], "bounds": [[1.0, 2.0]]}, hybc.ParameterError, "no parameter `hO`"),
        ({"names": ["e", "e"], "bounds": [[0.6, 0.9]] * 2}, hybc.ParameterError, "named twice"),
        (one(groups=["a"]), ValueError, "groups are not supported"),
        (one(num_vars=2), ValueError, "num_vars"),
        ({"names": ["e"]}, ValueError, "no 'bounds'"),
        ({"names": ["e", "h0"], "bounds": [[0.6, 0.9]]}, ValueError, "bounds has 1 entries for 2 names"),
        ({"names": "e", "bounds": [[0.6, 0.9]]}, TypeError, "the string 'e'"),
        ({"names": ["e"], "bounds": [["0.6", 0.9]]}, TypeError, "expected a number"),
        ([("e", 0.6, 0.9)], TypeError, "SALib's dict"),
    ]
    for problem, error, message in cases:
        with pytest.raises(error, match=message):
            ball.sobol(problem, ["energy"], 8)
    with pytest.raises(hybc.ParameterError, match="both in problem and in fixed"):
        ball.sobol(one(), ["energy"], 8, fixed={"e": 0.7})
    with pytest.raises(ValueError, match="outputs: .*nothing"):
        ball.sobol(one(), ["nothing"], 8)
    with pytest.raises(TypeError, match="outputs"):
        ball.sobol(one(), "energy", 8)
    with pytest.raises(ValueError, match='on_fail: expected "error", "drop" or "value=X"'):
        ball.sobol(one(), ["energy"], 8, on_fail="value=x")
    with pytest.raises(ValueError, match="bootstrap: 1 resample"):
        ball.sobol(one(), ["energy"], 8, bootstrap=1)
    with pytest.raises(ValueError, match="n: expected an integer >= 2"):
        ball.sobol(one(), ["energy"], 1)
    with pytest.raises(ValueError, match="rtol"):
        ball.sobol(one(), ["energy"], 8, rtol=-1)
    with pytest.warns(UserWarning, match="not a power of 2"):
        ball.sobol(one(), ["energy"], 12, t_end=1)


def test_without_bootstrap_there_are_no_intervals(ball):
    res = ball.sobol(BALL_PROBLEM, ["energy"], 16, bootstrap=0, second_order=True, t_end=2)["energy"]
    assert "S1_conf" not in res and "S2_conf" not in res
    assert res["S2"].shape == (3, 3)
    assert np.isnan(res["S2"][np.tril_indices(3)]).all()
    assert np.isfinite(res["S2"][np.triu_indices(3, 1)]).all()
