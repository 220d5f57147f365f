"""SALib's `sobol.analyze` on hybc's own design rows and outputs gives hybc's S1, ST and S2 to
round-off: the same estimators (Saltelli 2010 first order, Jansen total, Saltelli 2002 second
order) on the same rows. SALib's own sample is not compared (its scrambling differs), nor the
intervals (each draws its own bootstrap resamples). The rows are run again through `Model.sweep`
to show that the outputs SALib is given are those of the rows hybc reports.

Round-off: SALib standardises Y by its standard deviation, hybc only centres it, and the sums run
in different orders; for these outputs over 5,120 to 8,192 rows the indices differ by at most
1.7e-15 (measured); 1e-12 is asserted, far below any sampling error and far above round-off."""

import os

import numpy as np
import pytest

if os.environ.get("HYBC_CI"):
    import SALib  # noqa: F401 (CI installs SALib: a missing one is a failure, not a skip)
else:
    pytest.importorskip("SALib")

from SALib.analyze import sobol as salib_sobol

PROBLEM = {"num_vars": 3, "names": ["h0", "e", "g"], "bounds": [[0.5, 1.5], [0.75, 0.9], [9.0, 10.5]]}
ROUND_OFF = 1e-12


def salib(y, second_order):
    return salib_sobol.analyze(PROBLEM, y, calc_second_order=second_order, num_resamples=10, seed=1)


def assert_same_point_estimates(mine, theirs, second_order):
    np.testing.assert_allclose(mine["S1"], theirs["S1"], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(mine["ST"], theirs["ST"], rtol=0, atol=ROUND_OFF)
    if second_order:
        upper = np.triu_indices(3, 1)
        np.testing.assert_allclose(mine["S2"][upper], theirs["S2"][upper], rtol=0, atol=ROUND_OFF)


@pytest.mark.parametrize("second_order", [False, True])
def test_salib_gives_hybc_s_indices_on_hybc_s_rows(ball, second_order):
    n, t_end = 1024, 2.0  # no Zeno row before T = 2 over this prior
    res = ball.sobol(PROBLEM, ["energy", "touchdown#last"], n, seed=5, second_order=second_order, t_end=t_end)
    x = ball.sobol_design(PROBLEM, n, seed=5, second_order=second_order)
    table = ball.sweep(x, names=PROBLEM["names"], events=40, t_end=t_end)
    assert set(table["status"]) == {"ok"} and table["events"].max() < 40
    last = table["t1"].copy()
    for k in range(2, table["events"].max() + 1):
        last = np.where(table["events"] >= k, table[f"t{k}"], last)
    np.testing.assert_array_equal(res["energy"]["Y"], table["energy"])
    np.testing.assert_array_equal(res["touchdown#last"]["Y"], last)
    for label in res:
        assert_same_point_estimates(res[label], salib(res[label]["Y"], second_order), second_order)
    # Not a comparison that any numbers pass: the two outputs' indices differ.
    assert not np.allclose(res["energy"]["ST"], res["touchdown#last"]["ST"], atol=0.05)


def test_the_policies_are_salib_on_the_values_they_keep(ball):
    # At T = 1.6 the third touchdown fires for some rows only.
    n, block = 256, 5
    kw = dict(seed=0, t_end=1.6)
    value = ball.sobol(PROBLEM, ["touchdown#3"], n, on_fail="value=1.6", **kw)["touchdown#3"]
    y = value["Y"]
    missing = np.isnan(y)
    assert 0 < missing.sum() < len(y)
    assert_same_point_estimates(value, salib(np.where(missing, 1.6, y), False), False)
    drop = ball.sobol(PROBLEM, ["touchdown#3"], n, on_fail="drop", **kw)["touchdown#3"]
    kept = ~missing.reshape(n, block).any(axis=1)
    assert drop["base_points"] == kept.sum()
    assert_same_point_estimates(drop, salib(y.reshape(n, block)[kept].ravel(), False), False)
