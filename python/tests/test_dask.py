"""hybc.dask.sweep on a LocalCluster with two worker processes equals the local sweep exactly."""

import os

import numpy as np
import pytest

import hybc

if os.environ.get("HYBC_CI"):
    import distributed  # CI installs Dask: a missing one is a failure, not a skip
else:
    distributed = pytest.importorskip("distributed")

import hybc.dask


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )
    with distributed.Client(cluster) as client:
        yield client
    cluster.close()


def assert_tables_equal(a, b):
    assert list(a) == list(b)
    for name in a:
        assert a[name].dtype.kind == b[name].dtype.kind, name
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_equals_the_local_sweep(client, ball):
    points = hybc.grid(e=np.linspace(0.3, 0.95, 40), h0=[0.5, 1.0, 2.0])
    points["g"] = 9.5
    kw = dict(grad=["e", "h0"], events=4, t_end=5)  # some points end by Zeno
    local = ball.sweep(points, **kw)
    assert set(local["status"]) == {"ok", "zeno"}
    remote = hybc.dask.sweep(ball, points, client=client, shards=7, **kw)
    assert_tables_equal(remote, local)
    # One compiled model per worker process, however many shards it ran.
    info = client.run(hybc.dask._cache_info)
    assert len(info) == 2
    for cached in info.values():
        assert [list(c) for c in cached] == [["ball", [["e", "h0"]]]]


def test_fortran_points_and_default_shards(client, ball):
    rows = np.asfortranarray(np.column_stack([np.linspace(0.6, 0.9, 33), np.linspace(1, 2, 33)]))
    local = ball.sweep(rows, names=["e", "h0"], events=3)
    remote = hybc.dask.sweep(ball, rows, names=["e", "h0"], client=client, events=3)
    assert_tables_equal(remote, local)


def test_errors_are_raised_before_any_task(client, ball):
    with pytest.raises(hybc.ParameterError):
        hybc.dask.sweep(ball, {"e": [0.5, 2.0]}, client=client)
    with pytest.raises(ValueError, match="shards"):
        hybc.dask.sweep(ball, {"e": [0.5]}, client=client, shards=0)


def test_samples_are_drawn_on_the_workers_and_equal_the_local_draw(client, ball):
    samples = hybc.Samples(301, seed=11, ranges={"e": (0.6, 0.95), "h0": (0.5, 2.0)})
    local = ball.sweep(samples, grad=["h0"], events=2)
    remote = hybc.dask.sweep(ball, samples, client=client, shards=9, grad=["h0"], events=2)
    assert_tables_equal(remote, local)


def test_sobol_equals_the_local_analysis(client, ball):
    # T = 5: Zeno rows in some shards and not others, the drop policy and second order.
    problem = {"names": ["h0", "e", "g"], "bounds": [[0.5, 1.5], [0.75, 0.9], [9.0, 10.5]]}
    kw = dict(seed=7, second_order=True, on_fail="drop", t_end=5, bootstrap=50)
    local = ball.sobol(problem, ["energy", "touchdown#last"], 128, **kw)
    assert local.ended_early["zeno"] > 0
    remote = hybc.dask.sobol(ball, problem, ["energy", "touchdown#last"], 128, client=client, shards=7, **kw)
    assert list(remote) == list(local)
    assert (remote.ended_early, remote.first_ended_early_row, remote.runs) == (
        local.ended_early, local.first_ended_early_row, local.runs)
    for label in local:
        assert list(remote[label]) == list(local[label])
        for key, value in local[label].items():
            np.testing.assert_array_equal(remote[label][key], value, err_msg=f"{label} {key}")


def test_sobol_errors_are_raised_before_any_task(client, ball):
    with pytest.raises(hybc.ParameterError, match="declared range"):
        hybc.dask.sobol(ball, {"names": ["e"], "bounds": [[0.5, 2.0]]}, ["energy"], 8, client=client)
    with pytest.raises(ValueError, match="outputs"):
        hybc.dask.sobol(ball, {"names": ["e"], "bounds": [[0.5, 0.9]]}, ["nothing"], 8, client=client)
    with pytest.raises(ValueError, match="shards"):
        hybc.dask.sobol(ball, {"names": ["e"], "bounds": [[0.5, 0.9]]}, ["energy"], 8, client=client, shards=0)


def without_timings(report):
    report = dict(report)
    report.pop("run")
    stats = dict(report.pop("stats"))
    stats.pop("optimize_seconds")
    stats.pop("compile_seconds")
    return report, stats


@pytest.mark.parametrize("shards", [None, 3, 16])
def test_multi_start_optimisation_equals_the_local_one(client, ball, shards):
    # The ball's two-parameter exercise: 32 seeded starts over h0 in [0.5, 2] find three bounce
    # branches; spread over 2 workers in 2, 3 or 16 shards the report is the local one.
    problem = (["h0", "e"], "h0", ["energy = 2", "y = 0.1"])
    kw = dict(bounds={"h0": (0.5, 2), "e": (0.75, 0.95)}, starts=32, seed=1)
    local = ball.optimize(*problem, **kw)
    shared = hybc.dask.optimize(ball, *problem, client=client, shards=shards, **kw)
    assert len(local["optima"]) == 3, local["optima"]
    assert [o["starts"] for o in shared["optima"]] == [o["starts"] for o in local["optima"]]
    assert sorted(i for o in shared["optima"] for i in o["starts"]) == [
        s["index"] for s in local["starts"] if s["converged"]
    ]
    assert without_timings(shared) == without_timings(local)
    assert shared["run"].outputs["energy"] == local["run"].outputs["energy"]


def test_a_refused_multi_start_raises_as_the_local_one(client, ball):
    # h0 has no declared range: several starts need bounds for it.
    with pytest.raises(RuntimeError, match="has no finite range"):
        ball.optimize(["h0", "e"], "h0", ["energy = 2"], starts=4)
    with pytest.raises(RuntimeError, match="has no finite range"):
        hybc.dask.optimize(ball, ["h0", "e"], "h0", ["energy = 2"], starts=4, client=client)
