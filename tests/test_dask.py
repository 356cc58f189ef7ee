"""Tasks on a Dask cluster: bit-identical to in-process, retried once, failures named, others kept."""

import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from fixtures import demo_plugin  # noqa: E402

from workbench.report.cache import load_arrays  # noqa: E402
from workbench.report.engine import DaskClusterLost, InProcess, dask_executor, run_recipe, run_report  # noqa: E402
from workbench.specs import Task  # noqa: E402

TESTS = Path(__file__).parent


@pytest.fixture(scope="module")
def worker_path(tmp_path_factory):
    """Workers are new processes: they find the demo plugin through an entry point on PYTHONPATH."""
    site = demo_plugin.write_entry_point_site(tmp_path_factory.mktemp("site"))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PYTHONPATH", os.pathsep.join([str(site), str(TESTS), os.environ.get("PYTHONPATH", "")]))
        yield site


@pytest.fixture(scope="module")
def one_worker(worker_path):
    """One local cluster of one worker, shared by the tests of this module (starting one costs seconds)."""
    from workbench.plugins import load_host

    executor = dask_executor(load_host(extra_plugins=[("demo", demo_plugin)]), workers=1)
    yield executor
    executor.close()


@pytest.fixture(scope="module")
def inproc_fig1(tmp_path_factory):
    """The in-process report's figure data, the reference every cluster size must reproduce bit for bit."""
    from workbench.plugins import load_host

    out = tmp_path_factory.mktemp("inproc")
    run_report(load_host(extra_plugins=[("demo", demo_plugin)]), out, papers=["demo"], filters="+sir", seed=4,
               progress=False)
    return load_arrays(out / "paperdemo" / "fig1.npz")


@pytest.mark.parametrize("workers", [2, 1])  # 2 first: the shared one-worker cluster starts after it closes
def test_local_cluster_gives_bit_identical_results(tmp_path, demo_host, worker_path, inproc_fig1, request, workers):
    executor = request.getfixturevalue("one_worker") if workers == 1 else dask_executor(demo_host, workers=workers)
    try:
        report = run_report(demo_host, tmp_path / "dask", papers=["demo"], filters="+sir", seed=4, progress=False,
                            executor=executor)
    finally:
        if workers != 1:
            executor.close()
    assert not report.papers[0].errors
    a = inproc_fig1
    b = load_arrays(tmp_path / "dask" / "paperdemo" / "fig1.npz")
    assert list(a["filters"]) == list(b["filters"]) == ["ekf", "kf", "sir"]
    assert np.array_equal(a["mse"], b["mse"])  # bit-identical, the particle filter included


def _recipe_with(tmp_path, *extra):
    return replace(demo_plugin.RECIPE, tasks=lambda o: [*demo_plugin._tasks(o)[:1], *extra])


@pytest.mark.parametrize("use_dask", [False, True])
def test_a_task_failing_once_is_retried_and_one_failing_always_is_reported(tmp_path, demo_host, request, use_dask):
    recipe = _recipe_with(tmp_path, Task("flaky", {"marker": str(tmp_path / "marker")}, demo_plugin.flaky_task),
                          Task("doomed", {}, demo_plugin.always_fails))
    executor = request.getfixturevalue("one_worker") if use_dask else InProcess(demo_host)
    outcome = run_recipe(recipe, demo_host, tmp_path / "out", progress=False, executor=executor)
    status = {t["key"]: t["error"] for t in outcome.tasks}
    assert status["mse-kf"] == "" and status["flaky"] == ""
    assert "this chunk always fails" in status["doomed"]
    assert [e for e in outcome.errors if "doomed" in e]
    cached = sorted(p.name.split("-")[0] for p in (tmp_path / "out" / "cache" / "paperdemo").glob("*.npz"))
    assert cached == ["flaky", "mse"]


def test_a_cluster_whose_workers_are_gone_fails_in_one_line_instead_of_waiting_for_ever(tmp_path, demo_host,
                                                                                        worker_path, capsys):
    from workbench.cli import _os_message

    executor = dask_executor(demo_host, workers=1)
    address = executor.client.scheduler.address
    try:
        executor.cluster.scale(0)  # the workers are stopped; the scheduler stays up and would wait for ever
        deadline = time.monotonic() + 30
        while executor.client.nthreads() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not executor.client.nthreads()
        executor.no_worker_grace, executor.poll = 1.0, 0.2
        start = time.monotonic()
        with pytest.raises(DaskClusterLost) as caught:
            run_recipe(demo_plugin.RECIPE, demo_host, tmp_path / "out", progress=False, executor=executor)
        assert time.monotonic() - start < 20
    finally:
        executor.close()
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"the Dask cluster {address}: ")
    assert "no worker for 1 s while" in message and "tasks wait" in message
    # the command line prints it as one line: "workbench: error: cannot use the Dask cluster tcp://...: no worker ..."
    assert _os_message(caught.value) == f"cannot use {message}"
