"""hybc.Model.from_sbml: an SBML Test Suite case against its closed form; refusals point into the XML."""

import math
import pickle

import numpy as np
import pytest

import hybc
from conftest import REPO

CASE = REPO / "tests" / "data" / "sbml" / "00001" / "00001-sbml-l3v2.xml"


def test_an_sbml_case_runs_as_its_closed_form_with_gradients():
    # 00001: S1 -> S2 at rate k1 * S1 * compartment (compartment 1, k1 = 1, S1(0) = 1.5e-4):
    # S1(t) = S1(0) exp(-k1 t), S2 = S1(0) - S1, dS1/dk1 = -t S1.
    model = hybc.Model.from_sbml(CASE)
    assert model.params["k1"] == 1.0
    assert model.states == ["S1", "S2"]
    assert "model case00001" in model.source
    run = model.simulate({"k1": 0.7}, grad=["k1"], t_end=5, rtol=1e-10, atol=1e-16)
    assert run.ok and run.stopped_by == "t_end"
    s1 = 1.5e-4 * math.exp(-0.7 * 5)
    assert math.isclose(run.state["S1"], s1, rel_tol=1e-7)
    assert math.isclose(run.state["S2"], 1.5e-4 - s1, rel_tol=1e-7)
    np.testing.assert_allclose(run.dstate["S1"], [-5 * s1], rtol=1e-6)
    # The same document through Model.from_file (a path ending in .xml) is the same model.
    assert hybc.Model.from_file(CASE).source == model.source
    # Pickled as its .hyb text (Dask workers rebuild it): the same run, bit for bit.
    plain = model.simulate({"k1": 0.7}, t_end=5, rtol=1e-10, atol=1e-16)
    again = pickle.loads(pickle.dumps(model)).simulate({"k1": 0.7}, t_end=5, rtol=1e-10, atol=1e-16)
    assert again.state["S1"] == plain.state["S1"]


def test_a_refused_document_names_the_file_line_and_column(tmp_path):
    path = tmp_path / "dae.xml"
    path.write_text(
        """<?xml version="1.0" encoding="UTF-8"?>
<sbml xmlns="http://www.sbml.org/sbml/level3/version2/core" level="3" version="2">
  <model id="m">
    <listOfParameters><parameter id="x" value="1" constant="false"/></listOfParameters>
    <listOfRules>
      <algebraicRule><math xmlns="http://www.w3.org/1998/Math/MathML"><ci>x</ci></math></algebraicRule>
    </listOfRules>
  </model>
</sbml>
"""
    )
    with pytest.raises(hybc.ModelError, match=r"dae\.xml:6:7") as info:
        hybc.Model.from_sbml(path)
    assert "algebraic rule" in str(info.value)
