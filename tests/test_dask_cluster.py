"""Calibration through a real Dask cluster: a scheduler and two workers as separate processes."""

import json
import subprocess
import sys
import time

import pytest

distributed = pytest.importorskip("distributed")


@pytest.fixture
def cluster(tmp_path):
    """``dask scheduler`` and two ``dask worker`` processes on localhost; yields the address."""
    info = tmp_path / "scheduler.json"
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(info)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.time() + 60
        while not info.is_file() and time.time() < deadline:
            time.sleep(0.2)
        assert info.is_file(), "the scheduler did not start"
        for _ in range(2):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", "--nthreads", "1",
                                           "--nworkers", "1", "--no-dashboard", "--scheduler-file", str(info)],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        address = json.loads(info.read_text())["address"]
        with distributed.Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


@pytest.mark.slow
def test_calibration_runs_on_an_external_cluster(small_twin, tmp_path, cluster):
    folder, _ = small_twin
    with distributed.Client(cluster, timeout="30s") as client:
        before = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.transition_counter)
    cal = tmp_path / "cal"
    out = subprocess.run([sys.executable, "-m", "hifumotion", "calibrate", str(folder / "observed"), "-o", str(cal),
                          "--particles", "200", "--search-particles", "150", "--max-evaluations", "1",
                          "--scheduler-address", cluster], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr + out.stdout
    params = json.loads((cal / "parameters.json").read_text())
    assert params["fit"]["runs"] > 1
    with distributed.Client(cluster, timeout="30s") as client:
        after = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.transition_counter)
        workers = client.scheduler_info()["workers"]
    # the forward runs went through this scheduler, to its two workers
    assert after > before and len(workers) == 2
