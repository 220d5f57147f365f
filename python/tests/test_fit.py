"""Model.fit: the library's fit (what `hybc fit` runs) from Python, with measurements given as a
mapping of columns (a dict or a DataFrame), against closed forms and the CLI's report."""

from __future__ import annotations

import json
import math
import os
import subprocess

import numpy as np
import pytest

import hybc
from conftest import MODELS, REPO

# x' = -k x from x0: x(t) = x0 exp(-k t).
DECAY = """model decay
param k = 1 in [0.01, 10]
param x0 = 1 in [0, 10]
state x = x0
der(x) = -k * x
output y = 2 * x
"""


def test_noiseless_data_recovers_the_parameters_to_1e_8():
    model = hybc.Model(DECAY)
    t = np.linspace(0.0, 3.0, 16)
    y = 2 * 1.7 * np.exp(-0.6 * t)
    y[3] = np.nan  # a missing value is skipped
    report = model.fit(["k", "x0"], data={"time": t, "y": y}, params={"k": 1.0, "x0": 1.0}, t_end=3.0)
    assert report["converged"], report["message"]
    assert report["params"]["k"] == pytest.approx(0.6, rel=1e-8)
    assert report["params"]["x0"] == pytest.approx(1.7, rel=1e-8)
    assert report["data"]["by_name"][0]["count"] == 15


def test_a_dataframe_fit_equals_the_cli_fit_of_the_same_csv():
    pd = pytest.importorskip("pandas")
    csv = REPO / "examples/data/dosing_conc.csv"
    frame = pd.read_csv(csv)
    model = hybc.Model.from_file(MODELS / "dosing.hyb")
    report = model.fit(["ka", "ke"], data=frame)
    hybc_bin = REPO / "target/debug/hybc"
    if not hybc_bin.exists():
        if os.environ.get("HYBC_CI"):
            raise AssertionError(f"{hybc_bin} is missing: build it first (cargo build --bin hybc)")
        pytest.skip("the CLI is not built")
    cli = json.loads(
        subprocess.run(
            [hybc_bin, "fit", MODELS / "dosing.hyb", "--free", "ka,ke", "--data", csv, "--format", "json"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
    )
    for name in ("ka", "ke"):
        assert report["params"][name] == cli["params"][name]
        assert report["data"]["standard_errors"][name] == cli["data"]["standard_errors"][name]
    # The true values (1.3, 0.25) are within two standard errors.
    se = report["data"]["standard_errors"]
    assert abs(report["params"]["ka"] - 1.3) < 2 * se["ka"] and abs(report["params"]["ke"] - 0.25) < 2 * se["ke"]


def test_targets_as_strings_or_a_dict():
    # y(2) = 2 x0 exp(-2 k) = 1 with x0 = 1: k = ln(2) / 2.
    model = hybc.Model(DECAY)
    for targets in (["y@2=1"], {"y@2": 1.0}):
        report = model.fit(["k"], targets, t_end=3.0)
        assert report["converged"] and report["params"]["k"] == pytest.approx(math.log(2) / 2, rel=1e-9)


def test_bad_data_and_arguments_are_refused_with_the_cli_words():
    model = hybc.Model(DECAY)
    with pytest.raises(ValueError, match=r"column `z` is not an output or a state"):
        model.fit(["k"], data={"time": [0.0, 1.0], "z": [1.0, 2.0]})
    with pytest.raises(ValueError, match="no `time` column"):
        model.fit(["k"], data={"y": [1.0]})
    with pytest.raises(ValueError, match="differ in length"):
        model.fit(["k"], data={"time": [0.0, 1.0], "y": [1.0]})
    with pytest.raises(TypeError, match="expected numbers"):
        model.fit(["k"], data={"time": [0.0], "y": ["a"]})
    with pytest.raises(ValueError, match="a standard deviation must be positive"):
        model.fit(["k"], data={"time": [0.0], "y": [1.0], "sigma_y": [0.0]})
    with pytest.raises(ValueError, match="give targets= or data="):
        model.fit(["k"])
    with pytest.raises(hybc.ParameterError):
        model.fit(["nope"], ["y=1"])
    with pytest.raises(ValueError, match="max_iter"):
        model.fit(["k"], ["y=1"], max_iter=0)
    with pytest.warns(UserWarning, match="underdetermined"):
        model.fit(["k", "x0"], ["y=1"], t_end=1.0)
