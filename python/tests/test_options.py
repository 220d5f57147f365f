"""The simulation keywords and `hybc run`'s flags are one set of options with one set of checks
(`hybc::SimOverrides`): every keyword has its flag, and a bad value gets the same words from
both, the option named as each front end spells it (`rtol` / `--rtol`)."""

from __future__ import annotations

import os
import re
import subprocess

import pytest

import hybc
from conftest import MODELS, REPO


def cli(*args: str) -> subprocess.CompletedProcess:
    hybc_bin = REPO / "target/debug/hybc"
    if not hybc_bin.exists():
        if os.environ.get("HYBC_CI"):
            raise AssertionError(f"{hybc_bin} is missing: build it first (cargo build --bin hybc)")
        pytest.skip("the CLI is not built")
    return subprocess.run([hybc_bin, *args], capture_output=True, text=True)


def flag(keyword: str) -> str:
    return "--" + keyword.replace("_", "-")


def keywords() -> list[str]:
    """The keywords every entry point takes, as the message for an unknown one lists them."""
    with pytest.raises(TypeError) as refused:
        hybc.Model.from_file(MODELS / "ball.hyb").simulate(not_an_option=1)
    listed = re.search(r"the simulation keywords are (.*)\)", str(refused.value))
    assert listed, refused.value
    return listed.group(1).split(", ")


def test_every_keyword_is_a_flag_of_every_command_that_runs():
    # A switch is spelled on the command line by what it changes from the default.
    switches = {"sens_error_control": "--no-sens-error-control"}
    assert "h_max" in keywords() and "t_start" in keywords()
    for command in ("run", "sweep", "fit", "sobol", "periodic", "optimize"):
        help_text = cli(command, "--help").stdout
        for keyword in keywords():
            spelled = switches.get(keyword, flag(keyword))
            assert re.search(rf"{spelled}\b", help_text), f"hybc {command} has no {spelled} ({keyword}=)"


@pytest.mark.parametrize(
    "keyword, value",
    [
        ("rtol", -1.0),
        ("rtol", 1.0),
        ("atol", 0.0),
        ("graze_tol", -0.5),
        ("h_max", -0.5),
        ("max_events", 0),
        ("max_steps", 0),
        ("t_end", -1.0),
        ("t_start", 3.0),
    ],
)
def test_a_bad_value_gets_the_cli_words(keyword, value):
    model = hybc.Model.from_file(MODELS / "ball.hyb")
    with pytest.raises(ValueError) as refused:
        model.simulate(**{keyword: value})
    # `--flag=value`: clap reads a negative number after a space as a flag.
    run = cli("run", str(MODELS / "ball.hyb"), f"{flag(keyword)}={value:g}")
    assert run.returncode == 2, run.stderr
    words = run.stderr.strip().removeprefix("error: ")
    for name in ("t_start", "t_end", keyword):
        words = words.replace(flag(name), name)
    assert str(refused.value) == words
