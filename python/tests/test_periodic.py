"""Model.periodic: the library's orbit search (what `hybc periodic` runs) from Python, against
the CLI's report on the shipped walker and against the gait's own closed form of a fixed point."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

import hybc
from conftest import MODELS, REPO

WALKER = MODELS / "walker.hyb"
FREE = ["theta0", "dtheta0", "dphi0"]
# docs/periodic.md's command, 1% off Garcia et al.'s published gait (gamma = 0.009).
START = {"theta0": 0.2, "dtheta0": -0.2, "dphi0": -0.0158}


def cli_report(*args: str) -> dict:
    hybc_bin = REPO / "target/debug/hybc"
    if not hybc_bin.exists():
        if os.environ.get("HYBC_CI"):
            raise AssertionError(f"{hybc_bin} is missing: build it first (cargo build --bin hybc)")
        pytest.skip("the CLI is not built")
    out = subprocess.run([hybc_bin, "periodic", *args, "--format", "json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_the_walkers_orbit_is_the_clis_field_for_field_and_number_for_number():
    report = hybc.Model.from_file(WALKER).periodic("heelstrike", FREE, params=START)
    sets = [f"--set={name}={value!r}" for name, value in START.items()]
    cli = cli_report(str(WALKER), "--section", "heelstrike", "--free", ",".join(FREE), *sets)
    # The same fields in the same order, and every number the same to the bit: one library
    # (`hybc::PeriodicRequest`) behind both, printed by one report.
    assert list(report) == list(cli)
    assert report == cli
    # And it is the published gait: phi0 = 2 theta0 at the fixed point, stable, one trivial
    # multiplier (the section's).
    fixed = report["fixed_point"]
    assert fixed["theta"] == pytest.approx(0.200310900544287, abs=1e-8)
    assert fixed["phi"] == pytest.approx(2 * fixed["theta"], abs=1e-12)
    assert report["stable"] and report["trivial"] >= 1
    assert report["residuals"][-1] <= 1e-10 * (1 + abs(fixed["theta"]))


def test_a_later_firing_and_the_simulation_keywords_are_the_clis_too():
    model = hybc.Model.from_file(WALKER)
    report = model.periodic("heelstrike#2", FREE, params=START, rtol=1e-10, max_iter=20)
    sets = [f"--set={name}={value!r}" for name, value in START.items()]
    cli = cli_report(
        str(WALKER), "--section", "heelstrike#2", "--free", ",".join(FREE), *sets, "--rtol", "1e-10",
        "--max-iter", "20",
    )
    assert report == cli
    assert report["firing"] == 2 and report["events"] == 2 * model.periodic("heelstrike", FREE, params=START)["events"]


def test_refusals_name_the_argument_and_a_missing_orbit_is_a_runtime_error():
    model = hybc.Model.from_file(WALKER)
    with pytest.raises(ValueError, match="no event `toe`"):
        model.periodic("toe", FREE, params=START)
    with pytest.raises(ValueError, match="section: `heelstrike#0`: expected EVENT or EVENT#K"):
        model.periodic("heelstrike#0", FREE, params=START)
    with pytest.raises(hybc.ParameterError, match="no parameter `theta9`"):
        model.periodic("heelstrike", ["theta9"], params=START)
    with pytest.raises(ValueError, match="tol: expected a positive number, found -1"):
        model.periodic("heelstrike", FREE, params=START, tol=-1.0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'rtoll'"):
        model.periodic("heelstrike", FREE, params=START, rtoll=1e-8)
    # One Newton iteration from 1% off is not enough: no fixed point, as `hybc periodic` exits 4.
    with pytest.raises(RuntimeError, match="no fixed point found: after 1 Newton iterations"):
        model.periodic("heelstrike", FREE, params={k: 1.01 * v for k, v in START.items()}, max_iter=1)


KICKED = REPO / "tests/data/periodic/kicked.hyb"
BRAKED = REPO / "tests/data/cli/periodic_not_verified_json/model.hyb"


def cli_json(*args: str) -> tuple[int, dict]:
    hybc_bin = REPO / "target/debug/hybc"
    if not hybc_bin.exists():
        if os.environ.get("HYBC_CI"):
            raise AssertionError(f"{hybc_bin} is missing: build it first (cargo build --bin hybc)")
        pytest.skip("the CLI is not built")
    out = subprocess.run([hybc_bin, "periodic", *args, "--format", "json"], capture_output=True, text=True)
    return out.returncode, json.loads(out.stdout)


def test_the_kicked_oscillators_second_kick_and_its_verdict_are_the_clis():
    # The one-kick orbit twice (closed forms in tests/it/periodic.rs): v0 = -k / (1 - rho),
    # multipliers rho^2 and 0, verified by a run of the model; stable.
    report = hybc.Model.from_file(KICKED).periodic("kick#2", ["v0"])
    code, cli = cli_json(str(KICKED), "--section", "kick#2", "--free", "v0")
    assert code == 0 and report == cli
    assert report["found"] and report["stability"] == "stable" and report["stable"]
    assert report["fixed_point"]["v"] == pytest.approx(-2.135848886916229, abs=1e-10)
    assert report["multipliers"][0][0] == pytest.approx(0.5318020829442597**2, abs=1e-10)
    assert report["verification"]["residual"] <= 1e-10 * (1 + abs(report["fixed_point"]["v"]))
    # Undamped and unkicked: a neutral multiplier, borderline.
    neutral = hybc.Model.from_file(KICKED).periodic("kick", ["v0"], params={"c": 0.0, "k": 0.0})
    assert neutral["stability"] == "borderline" and not neutral["stable"]


def test_a_search_that_finds_nothing_raises_with_the_clis_report():
    # A brake that the kick sets off: the return map closes, a run of the model does not come
    # back (exit 4, not_verified); the RuntimeError's report is the CLI's JSON.
    with pytest.raises(RuntimeError, match="a run of the model from it returns") as raised:
        hybc.Model.from_file(BRAKED).periodic("kick", ["v0"])
    code, cli = cli_json(str(BRAKED), "--section", "kick", "--free", "v0")
    assert code == 4 and raised.value.report == cli
    assert cli["found"] is False and cli["reason"] == "not_verified"
    # A run that misses the section (exit 3): the same.
    with pytest.raises(RuntimeError, match="does not reach the section") as raised:
        hybc.Model.from_file(WALKER).periodic("heelstrike", ["theta0"], params={"dtheta0": 0.5})
    code, cli = cli_json(str(WALKER), "--section", "heelstrike", "--free", "theta0", "--set", "dtheta0=0.5")
    assert code == 3 and raised.value.report == cli and cli["reason"] == "missed_section"
