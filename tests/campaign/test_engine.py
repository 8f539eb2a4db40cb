"""Campaigns on Dask: every run recorded once, failures with their reasons, nothing computed
twice on a second invocation, a worker killed mid-campaign, a killed driver, and the cluster
path through --address with the scheduler and a worker as separate processes."""

from __future__ import annotations

import logging
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.campaign import funcs
from utrf.campaign import engine, spec
from utrf.campaign.store import Store

ROOT = Path(__file__).resolve().parents[2]


def function_campaign(tmp_path: Path, xs: str, sleep_s: float = 0.0, extra: str = "") -> Path:
    path = tmp_path / "f.toml"
    path.write_text(
        f'[campaign]\nname = "f"\nkind = "function"\n\n[sampler]\nmethod = "grid"\n{extra}\n'
        f"[parameters]\nx = {xs}\ny = [0.0]\nsleep_s = {sleep_s}\n\n"
        '[options]\nfunction = "tests.campaign.funcs:square"\n'
    )
    return path


def traced(trace: Path) -> list[float]:
    return [float(line.split()[0]) for line in trace.read_text().splitlines()] if (
        trace.exists()) else []  # fmt: skip


@pytest.fixture(scope="module")
def address() -> Iterator[str]:
    """One local cluster (2 single-threaded worker processes) for the module's campaigns."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=logging.ERROR) as cluster:  # fmt: skip
        yield cluster.scheduler_address


@pytest.fixture()
def trace(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, address: str) -> Path:
    """Every call of the test function, one line each (the workers see the variable)."""
    from distributed import Client

    path = tmp_path / "trace.txt"
    with Client(address) as client:
        client.run(funcs.set_trace, str(path))
    # A worker the nanny restarts (after a kill) inherits the nanny's environment: this process's.
    monkeypatch.setenv("UTRF_TEST_TRACE", str(path))
    return path


def run_rows(out: Path) -> list[dict]:
    return pq.read_table(out / "results.parquet").to_pylist()


@pytest.mark.slow
def test_runs_are_recorded_once_with_failures_and_never_computed_twice(
    tmp_path: Path, address: str, trace: Path
) -> None:
    c = spec.load(function_campaign(tmp_path, "[-2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 3.0]"))
    lines: list[str] = []
    s = engine.run(c, tmp_path / "out", address=address, progress=lines.append)
    rows = run_rows(tmp_path / "out")
    assert len(rows) == 6 and s.ok == 4 and s.failed == 2  # 3.0 twice is one run
    assert len({r["run_key"] for r in rows}) == 6
    bad = [r for r in rows if r["status"] == "failed"]
    assert {r["x"] for r in bad} == {-2.0, -1.0}
    assert all("ValueError: x must be >= 0" in r["error"] for r in bad)
    assert {r["x"]: r["f"] for r in rows if r["status"] == "ok"} == {0.0: 0, 1.0: 1, 2.0: 4,
                                                                      3.0: 9}  # fmt: skip
    assert "done 6/6 (2 failed" in lines[-1]
    assert sorted(traced(trace)) == [-2.0, -1.0, 0.0, 1.0, 2.0, 3.0]
    again = engine.run(c, tmp_path / "out", address=address, progress=lines.append)
    assert again.skipped == 6 and again.ok + again.failed == 0
    assert len(traced(trace)) == 6  # nothing computed again
    assert len(run_rows(tmp_path / "out")) == 6


@pytest.mark.slow
def test_a_small_design_sweep_and_its_report(tmp_path: Path, address: str) -> None:
    from utrf.campaign import report

    text = (ROOT / "host/utrf/data/campaigns/design-sweep.toml").read_text()
    text = text.replace("samples = 100000", "samples = 600").replace(
        "seed = 0", "seed = 0\nchunk = 100"
    )
    (tmp_path / "d.toml").write_text(text)
    s = engine.run(spec.load(tmp_path / "d.toml"), tmp_path / "d", address=address,
                   progress=lambda _: None)  # fmt: skip
    assert s.ok == 600 and s.failed == 0
    table = pq.read_table(tmp_path / "d" / "results.parquet")
    assert table.num_rows == 600 and len(set(table.column("run_key").to_pylist())) == 600
    assert len(Store(tmp_path / "d").part_files()) >= 1
    out = report.report(tmp_path / "d", plots=True)
    d = out["design"]
    assert 0 < d["front_size"] <= d["plan_safe"] <= 600 and (tmp_path / "d" / "front.png").exists()
    # every front design is accepted, and no accepted design beats one on every objective
    safe = [r for r in table.to_pylist() if r["plan_safe"]]
    for f in d["front"]:
        assert not any(
            r["link3_area_m2"] > f["link3_area_m2"]
            and r["stiffness_straight_n_per_m"] > f["stiffness_straight_n_per_m"]
            and r["largest_tension_n"] < f["largest_tension_n"]
            for r in safe
        )


@pytest.mark.slow
def test_an_optuna_search_runs_and_resumes_without_recomputing(
    tmp_path: Path, address: str, trace: Path
) -> None:
    path = tmp_path / "s.toml"
    path.write_text(
        '[campaign]\nkind = "function"\n[sampler]\nmethod = "optuna"\ntrials = 6\n'
        "[parameters]\nx = { min = 0.0, max = 3.0 }\ny = [0.0, 1.0]\n"
        '[objectives]\ng = "min"\n[options]\nfunction = "tests.campaign.funcs:square"\n'
    )
    s = engine.run(spec.load(path), tmp_path / "s", address=address, progress=lambda _: None)
    assert s.ok == 6 and len(traced(trace)) == 6
    again = engine.run(spec.load(path), tmp_path / "s", address=address, progress=lambda _: None)
    assert again.skipped == 6 and len(traced(trace)) == 6
    assert len(run_rows(tmp_path / "s")) == 6


@pytest.mark.slow
def test_a_worker_killed_mid_campaign_loses_no_run_and_doubles_none(
    tmp_path: Path, address: str, trace: Path
) -> None:
    from distributed import Client

    xs = "[" + ", ".join(f"{x}.0" for x in range(12)) + "]"
    c = spec.load(function_campaign(tmp_path, xs, sleep_s=0.4))
    with Client(address) as client:
        pids = list(client.run(os.getpid).values())
    killed = []

    def progress(line: str) -> None:  # once runs are under way, kill one worker's process
        if not killed and len(traced(trace)) >= 3:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    s = engine.run(c, tmp_path / "out", address=address, progress=progress)
    assert killed, "the campaign ended before a worker could be killed"
    rows = run_rows(tmp_path / "out")
    assert sorted(r["x"] for r in rows) == [float(x) for x in range(12)]  # none lost or doubled
    assert all(r["status"] == "ok" for r in rows) and s.ok == 12
    assert len(traced(trace)) >= 12  # the killed worker's run was done again elsewhere


@pytest.mark.slow
def test_a_killed_driver_resumes_and_computes_nothing_twice(
    tmp_path: Path, address: str, trace: Path
) -> None:
    xs = "[" + ", ".join(f"{x}.0" for x in range(16)) + "]"
    path = function_campaign(tmp_path, xs, sleep_s=0.3)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "utrf", "campaign", "run", str(path), "--out", str(out),
           "--address", address]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    driver = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not Store(out).part_files() and time.monotonic() < deadline:
        time.sleep(0.1)
    driver.kill()
    driver.wait()
    first = {r["x"] for r in Store(out).read().to_pylist()}
    assert 0 < len(first) < 16, "kill the driver mid-campaign"
    seen = len(traced(trace))
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    # the killed driver's tasks still running on the cluster finish and write their rows: at
    # least what was stored at the kill is done; a task run again writes its part again
    before = int(re.search(r"(\d+) already done", done.stdout).group(1))  # type: ignore[union-attr]
    assert len(first) <= before < 16
    rows = run_rows(out)
    assert sorted(r["x"] for r in rows) == [float(x) for x in range(16)]  # none twice
    assert not first & set(traced(trace)[seen:])  # what was stored is not computed again


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.slow
def test_the_cluster_path_with_a_separate_scheduler_and_worker(tmp_path: Path) -> None:
    dask = Path(sys.executable).with_name("dask")
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "UTRF_TEST_TRACE": str(tmp_path / "t.txt")}
    scheduler = subprocess.Popen(
        [str(dask), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    worker = subprocess.Popen(
        [str(dask), "worker", f"tcp://127.0.0.1:{port}", "--nworkers", "1", "--nthreads", "1",
         "--no-dashboard", "--host", "127.0.0.1"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        path = function_campaign(tmp_path, "[1.0, 2.0, -1.0]")
        done = subprocess.run(
            [sys.executable, "-m", "utrf", "campaign", "run", str(path), "--out",
             str(tmp_path / "out"), "--address", f"tcp://127.0.0.1:{port}"],
            env=env, capture_output=True, text=True, timeout=240,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert "cluster tcp://127.0.0.1" in done.stdout and "1 worker(s)" in done.stdout
        rows = run_rows(tmp_path / "out")
        assert sorted(r["x"] for r in rows) == [-1.0, 1.0, 2.0]
        workers = {r["worker"] for r in rows}
        assert len(workers) == 1 and str(worker.pid) not in workers  # a process of its own
        assert np.isclose(sorted(r["f"] for r in rows if r["f"] is not None), [1, 4]).all()
    finally:
        for p in (worker, scheduler):
            p.terminate()
        for p in (worker, scheduler):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


@pytest.mark.slow  # the client waits its 10 s connect timeout
def test_no_scheduler_at_the_address_is_a_clear_error(tmp_path: Path) -> None:
    from utrf.cli import main

    path = function_campaign(tmp_path, "[1.0]")
    port = free_port()
    code = main(["campaign", "run", str(path), "--out", str(tmp_path / "o"), "--address",
                 f"tcp://127.0.0.1:{port}"])  # fmt: skip
    assert code == 3


@pytest.mark.slow
def test_a_grasp_campaign_on_the_twin_records_holds_and_a_broken_firmware(
    tmp_path: Path, address: str
) -> None:
    from utrf.artifacts import firmware_elf

    (tmp_path / "broken.elf").write_bytes(b"not an ELF at all")
    path = tmp_path / "g.toml"
    path.write_text(
        '[campaign]\nkind = "grasp"\n[sampler]\nmethod = "grid"\n[parameters]\n'
        'firmware = ["real", "broken"]\nobject = ["ball"]\nmass_kg = 0.15\nduration_s = 3.0\n'
        f'hits = 1\nkp = 25.0\n[firmware]\nreal = "{firmware_elf()}"\nbroken = "broken.elf"\n'
    )
    s = engine.run(spec.load(path), tmp_path / "g", address=address, progress=lambda _: None)
    rows = {r["firmware"]: r for r in run_rows(tmp_path / "g")}
    assert s.ok == 1 and s.failed == 1
    real, broken = rows["real"], rows["broken"]
    assert real["status"] == "ok" and isinstance(real["held"], bool)
    assert real["largest_contact_force_n"] > 0 and real["firmware_build_id"]
    assert real["largest_tracking_error_rad"] >= 0 and real["slip_mm"] >= 0
    assert broken["status"] == "failed" and broken["error"]


def _twin_threads_env() -> str:
    return os.environ.get(engine.TWIN_THREADS_ENV, "")


@pytest.mark.slow
def test_the_local_workers_twin_threads_the_engines_choice_or_the_drivers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A lone worker on 2 cores or more gets two twin threads; a driver that sets
    UTRF_TWIN_THREADS (the benchmark: the same work a run on 1 worker and on 2) gets its own."""
    monkeypatch.delenv(engine.TWIN_THREADS_ENV, raising=False)
    lone = "2" if (os.cpu_count() or 1) >= 2 else "1"
    with engine.cluster(None, 1) as client:
        assert set(client.run(_twin_threads_env).values()) == {lone}
    monkeypatch.setenv(engine.TWIN_THREADS_ENV, "1")
    with engine.cluster(None, 1) as client:
        assert set(client.run(_twin_threads_env).values()) == {"1"}
    monkeypatch.setenv(engine.TWIN_THREADS_ENV, "3")  # refused before a worker starts
    with (
        pytest.raises(engine.CampaignError, match="UTRF_TWIN_THREADS must be 1 or 2"),
        engine.cluster(None, 1),
    ):
        pass
