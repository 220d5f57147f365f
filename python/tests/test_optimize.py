"""Model.optimize: the library's optimisation (what `hybc optimize` runs) from Python, against
the CLI's report and the constraints it claims to meet, with the run at the optimum."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

import hybc
from conftest import MODELS, REPO

BALL_ARGS = ["--free", "h0,e", "--minimize", "h0", "--subject-to", "energy = 2", "--subject-to", "y = 0.1",
             "--bounds", "h0=0.5:2"]


def cli(model: str, args: list[str]) -> dict:
    hybc_bin = REPO / "target/debug/hybc"
    if not hybc_bin.exists():
        if os.environ.get("HYBC_CI"):
            raise AssertionError(f"{hybc_bin} is missing: build it first (cargo build --bin hybc)")
        pytest.skip("the CLI is not built")
    out = subprocess.run([hybc_bin, "optimize", MODELS / model, *args, "--format", "json", "--quiet"],
                         capture_output=True, text=True)
    return json.loads(out.stdout)


def test_the_balls_two_parameter_exercise_equals_the_cli_and_its_run_meets_the_constraints():
    model = hybc.Model.from_file(MODELS / "ball.hyb")
    r = model.optimize(["h0", "e"], "h0", ["energy = 2", "y = 0.1"], bounds={"h0": (0.5, 2)})
    assert r["converged"], r["message"]
    assert r["optimum"] == cli("ball.hyb", BALL_ARGS)["optimum"]
    run = r["run"]
    assert run.outputs["energy"] == pytest.approx(2.0, abs=1e-8)
    assert run.state["y"] == pytest.approx(0.1, abs=1e-8)
    # The run has gradients with respect to the free parameters (the optimiser's Jacobian).
    assert len(run.doutputs["energy"]) == 2


def test_several_starts_find_several_bounce_branches():
    model = hybc.Model.from_file(MODELS / "ball.hyb")
    # 32 starts: e ranges over [0, 1], and half the starts fail (Zeno before T) or end infeasible;
    # with 16 only one branch was left (`hybc optimize ... --bounds h0=0.5:2 --starts 16 --seed 1`).
    r = model.optimize(["h0", "e"], "h0", ["energy = 2", "y = 0.1"], bounds={"h0": (0.5, 2)}, starts=32, seed=1)
    assert len(r["optima"]) >= 2, r["optima"]
    # Several branches: the 5-bounce one and at least one of the 4-bounce ones (falling and rising
    # at T have the same count), each optimum its own point.
    counts = {len(o["events"]) for o in r["optima"]}
    assert counts <= {4, 5} and len(counts) == 2, r["optima"]
    h0s = sorted(o["params"]["h0"] for o in r["optima"])
    assert all(b - a > 1e-6 for a, b in zip(h0s, h0s[1:])), h0s


def test_the_hoppers_least_effort_apex_from_a_vector_of_thrusts():
    model = hybc.Model.from_file(MODELS / "hopper_apex.hyb")
    r = model.optimize(["u"], "effort", ["y >= 0.9"])
    assert r["converged"], r["message"]
    (apex,) = r["constraints"]
    assert apex["met"] and apex["active"]
    assert r["run"].state["y"] == pytest.approx(0.9, abs=1e-7)


def test_bad_problems_are_refused_with_the_cli_words():
    model = hybc.Model.from_file(MODELS / "ball.hyb")
    with pytest.raises(ValueError, match="minimize"):
        model.optimize(["h0"], "nope")
    with pytest.raises(ValueError, match="subject_to"):
        model.optimize(["h0"], "h0", ["energy ~ 2"])
    with pytest.raises(ValueError, match="leaves its declared range"):
        model.optimize(["e"], "e", bounds={"e": (0.5, 2.0)})
    with pytest.raises(hybc.ParameterError):
        model.optimize(["nope"], "h0")
    with pytest.raises(ValueError, match="starts"):
        model.optimize(["e"], "e", starts=0)


def test_the_solver_keyword_picks_and_refuses_as_the_cli_flag_does():
    model = hybc.Model.from_file(MODELS / "ball.hyb")
    # Bounds alone: L-BFGS-B when asked (SLSQP for one parameter under auto), to the same end as
    # the CLI's, h0 held at its lower bound.
    args = ["--free", "h0", "--minimize", "h0", "--bounds", "h0=0.5:2", "--solver", "lbfgsb"]
    r = model.optimize(["h0"], "h0", bounds={"h0": (0.5, 2)}, solver="lbfgsb")
    assert r["converged"] and r["solver"] == "L-BFGS-B", r["message"]
    assert r["optimum"] == cli("ball.hyb", args)["optimum"] == {"h0": 0.5}
    assert model.optimize(["h0"], "h0", bounds={"h0": (0.5, 2)})["solver"] == "SLSQP"
    # General constraints need SLSQP; an unknown word and a count above the cap are refused.
    with pytest.raises(ValueError, match="solver: lbfgsb takes bounds only, not general constraints: use slsqp"):
        model.optimize(["h0", "e"], "h0", ["energy = 2"], solver="lbfgsb")
    with pytest.raises(ValueError, match="solver: expected auto, slsqp or lbfgsb, found `bfgs`"):
        model.optimize(["h0"], "h0", solver="bfgs")
    big = hybc.Model("model big\nparam u[1001] = 0 in [-1, 1]\nstate x = 0\nder(x) = u[0]\noutput y = x\n")
    with pytest.raises(ValueError, match=r"the cap of SLSQP\): at most 1000, found 1001"):
        big.optimize(["u"], "y", ["y <= 1"])
