"""Running a campaign on Dask (distributed): the runs not yet done, as tasks, on a cluster.

Local by default: a ``LocalCluster`` of one single-threaded worker process per core, made
and closed here (no set-up), with Dask's monitoring turned down (``LOCAL_CONFIG``). ``address``:
a scheduler the user already runs (``dask scheduler`` / ``dask worker``, or any deployment).
Dask schedules, balances and, when a worker dies, runs its tasks again on another; this
module keeps a window of tasks submitted and says how far it is. Each task writes its own
rows (``kinds.task``) and hands back a few numbers, so the driver's work per task is small
and does not grow with the task. Nothing here queues, schedules or pools work of its own.
"""

from __future__ import annotations

import itertools
import logging
import math
import os
import queue
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from utrf.campaign import kinds, sampling
from utrf.campaign.sampling import Columns
from utrf.campaign.spec import Campaign, CampaignError
from utrf.campaign.store import Store, columns_table
from utrf.emulator import twin_threads
from utrf.emulator.board_types import EmulatorError

ProgressFn = Callable[[str], None]
TICK_S = 1.0  # progress at most this often
TAIL_CHUNKS = 4  # the last this many tasks' runs go in quarter tasks (a short wait at the end)
# Dask's own settings on the local cluster. Its monitoring turned down: the workers'
# statistical profiler (a stack sample every 10 ms), the event loops' tick (20 ms), the system
# and memory monitors; idle, they took 9 % of a core across the driver, 2 workers and their
# nannies, 2.4 % with these (docs/benchmarks.md, Campaigns). And the workers' environment
# without MALLOC_TRIM_THRESHOLD_=65536 (which hands freed memory back to the system at once:
# numpy's temporaries are then page-faulted in anew, 10x the faults, a design 25 us of CPU
# instead of 14 us). Nothing a campaign uses depends on them.
LOCAL_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "2s",
    "distributed.nanny.pre-spawn-environ": {
        "OMP_NUM_THREADS": 1,
        "MKL_NUM_THREADS": 1,
        "OPENBLAS_NUM_THREADS": 1,
    },
}
# The twin's threads a run (the MCU and the plant on one core or two): one where a worker
# shares its cores with another; the emulator reads it (``utrf.emulator.twin_threads``).
TWIN_THREADS_ENV = twin_threads.ENV


@dataclass
class Summary:
    total: int  # runs in the campaign
    skipped: int  # already done before this invocation
    ok: int
    failed: int
    wall_s: float  # from the first task submitted to the last task's summary received
    busy_s: float  # the tasks' time on the workers (the runs and writing their rows), summed
    workers: int
    startup_s: float  # making (or reaching) the cluster
    cpu_s: float = 0.0  # the runs' CPU time, summed over workers
    compute_s: float = 0.0  # the runs' own time (without writing their rows), summed
    task_cpu_s: float = 0.0  # the tasks' CPU time on the workers (runs and rows), summed
    spans: list[tuple[str, float, float]] = field(default_factory=list)  # worker, start, end
    started_at: float = 0.0  # wall clock (time.time) at the first task submitted
    driver_cpu_s: float = 0.0  # this process's CPU over wall_s (a local scheduler's included)

    @property
    def overhead(self) -> float:
        """The share of the workers' wall time not spent in tasks (the engine's, the
        driver's and idle time at the start and the end)."""
        capacity = self.wall_s * max(self.workers, 1)
        return max(0.0, 1.0 - self.busy_s / capacity) if capacity > 0 else 0.0

    def add_task(self, r: dict[str, Any]) -> None:
        """A task's summary (``outcome``) counted: its runs' times and its span."""
        self.compute_s += r["compute_s"]
        self.cpu_s += r["cpu_s"]
        self.task_cpu_s += r.get("task_cpu_s", 0.0)
        if "start" in r:
            self.busy_s += r["end"] - r["start"]
            self.spans.append((r.get("worker", ""), r["start"], r["end"]))

    def line(self) -> str:
        rate = (self.ok + self.failed) / self.wall_s if self.wall_s > 0 else 0.0
        return (
            f"{self.ok + self.failed} runs ({self.ok} ok, {self.failed} failed; "
            f"{self.skipped} already done) in {self.wall_s:.1f} s on {self.workers} worker(s): "
            f"{rate * 3600:.0f} runs/h, engine and idle {self.overhead * 100:.1f} % of wall"
        )


@contextmanager
def cluster(address: str | None, workers: int | None) -> Iterator[Any]:
    """A Dask client: to ``address``, or to a new local cluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if address:
        try:
            client = Client(address, timeout="10s")
        except OSError as exc:
            raise CampaignError(f"no Dask scheduler at {address}: {exc}") from None
        with client:
            yield client
        return
    import dask

    n = workers or os.cpu_count() or 1
    shared = 2 * n > (os.cpu_count() or 1)  # two twin threads a worker would share cores
    # the driver's own UTRF_TWIN_THREADS, when set, wins (the same work a run on any count);
    # read and checked where the emulator reads it, so a bad value is refused before any run
    threads = "1" if shared else "2"
    if os.environ.get(TWIN_THREADS_ENV, "").strip():
        try:
            threads = str(twin_threads.plant_threads())
        except EmulatorError as exc:
            raise CampaignError(str(exc)) from None
    with (
        dask.config.set(LOCAL_CONFIG),
        LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            silence_logs=logging.ERROR,
            env={TWIN_THREADS_ENV: threads},
        ) as local,
        Client(local) as client,
    ):
        yield client


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "unknown"
    s = round(seconds)
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


class _Progress:
    """done, running, failed, rate and time left, at most once a ``TICK_S``."""

    def __init__(self, total: int, skipped: int, report: ProgressFn) -> None:
        self.total, self.skipped, self.report = total, skipped, report
        self.ok = self.failed = 0
        self.start = time.monotonic()
        self.last = 0.0

    def add_task(self, r: dict[str, Any]) -> None:
        self.ok += r["ok"]
        self.failed += r["rows"] - r["ok"]

    def tick(self, running: int, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self.last < TICK_S:
            return
        self.last = now
        done = self.ok + self.failed
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        left = self.total - self.skipped - done
        eta = left / rate if rate > 0 else math.inf
        self.report(
            f"done {self.skipped + done}/{self.total} ({self.failed} failed, "
            f"{self.skipped} from before), running {running}, {rate:.3g} runs/s, "
            f"time left {_duration(eta) if left else '0:00:00'}"
        )


def failed_table(cols: Columns, words: np.ndarray, reason: str) -> pa.Table:
    """Rows for runs whose task died (its worker lost more often than Dask allows)."""
    n = len(words)
    return columns_table(
        {
            "run_key": sampling.hex_keys(words),
            "worker": np.full(n, ""),
            "status": np.full(n, "failed"),
            "error": np.full(n, reason, dtype=object),
            "compute_s": np.zeros(n),
            "cpu_s": np.zeros(n),
            **cols,
        }
    )


def outcome(
    fut: Any, cols: Columns, idx: np.ndarray, words: np.ndarray, store: Store
) -> dict[str, Any]:
    """A finished task's summary (its runs: ``idx`` of ``cols`` and ``words``); its rows
    written here if the worker could not (or the task died)."""
    if fut.status == "finished":
        r: dict[str, Any] = fut.result()
    else:  # the task itself died (a worker lost too often): its runs failed
        exc = fut.exception()
        part = {k: v[idx] for k, v in cols.items()}
        t = failed_table(part, words[idx], f"{type(exc).__name__}: {exc}")
        r = {"rows": t.num_rows, "ok": 0, "compute_s": 0.0, "cpu_s": 0.0, "table": t}
    fut.release()
    if r.get("table") is not None:
        store.append(r.pop("table"))
    return r


def salt(campaign: Campaign) -> str:
    return f"{campaign.kind}|{campaign.digest}"


def sink(store: Store, token: str) -> kinds.Sink:
    return kinds.Sink(str(store.parts.resolve()), token)


def chunks(n: int, size: int) -> list[slice]:
    """Tasks over ``n`` runs: ``size`` runs each, the last ``TAIL_CHUNKS`` tasks' runs in
    quarters (so the last tasks end close together). Depends on ``n`` and ``size`` alone:
    a campaign run again cuts the same tasks, and a task's part has the same name."""
    tail = min(n, TAIL_CHUNKS * size) if size >= 4 else 0
    head = n - tail
    cuts = [*range(0, head, size), *range(head, n, max(1, size // 4)), n]
    return [slice(a, b) for a, b in itertools.pairwise(cuts) if b > a]


def run(
    campaign: Campaign,
    out: Path,
    *,
    address: str | None = None,
    workers: int | None = None,
    progress: ProgressFn = print,
) -> Summary:
    """Run every run of ``campaign`` not already in ``out``; the workers write them."""
    kind = kinds.get(campaign.kind)
    kind.check(campaign)
    store = Store(out)
    to = sink(store, store.claim(campaign))
    if campaign.method == "optuna":
        from utrf.campaign import search

        return search.run(campaign, store, to, address=address, workers=workers, progress=progress)
    cols = sampling.columns(campaign)
    words = sampling.key_words(cols, salt(campaign))
    order = np.sort(np.unique(words, return_index=True)[1])  # a run listed twice runs once
    total = len(order)
    done = store.done_words()
    tasks = []
    for s in chunks(total, campaign.chunk or kind.chunk):
        idx = order[s]
        if len(done):
            idx = idx[~np.isin(words[idx], done)]
        if len(idx):
            tasks.append(idx)
    todo = sum(len(t) for t in tasks)
    if not tasks:  # everything is done: no cluster to start
        progress(f"done {total}/{total} ({total} from before)")
        store.consolidate()
        return Summary(total, total, 0, 0, 0.0, 0.0, 0, 0.0)
    t0 = time.monotonic()
    with cluster(address, workers) as client:
        client.run(kinds.warm, campaign.kind)
        startup = time.monotonic() - t0
        n_workers = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
        prog = _Progress(total, total - todo, progress)
        summary = _drive(client, campaign, cols, words, tasks, store, to, prog, n_workers)
    summary.startup_s = startup
    store.consolidate()
    return summary


def _drive(
    client: Any,
    campaign: Campaign,
    cols: Columns,
    words: np.ndarray,
    tasks: list[np.ndarray],
    store: Store,
    to: kinds.Sink,
    prog: _Progress,
    n_workers: int,
) -> Summary:
    window = 2 * n_workers  # enough queued that no worker waits for the driver
    pending = list(reversed(tasks))
    by_future: dict[Any, np.ndarray] = {}
    s = Summary(prog.total, prog.skipped, 0, 0, 0.0, 0.0, n_workers, 0.0)
    options = {**campaign.options, "firmware_paths": campaign.firmware}
    finished: queue.SimpleQueue[Any] = queue.SimpleQueue()  # futures done, from Dask's thread
    start, s.started_at, cpu0 = time.perf_counter(), time.time(), time.process_time()

    def submit() -> None:
        while pending and len(by_future) < window:
            idx = pending.pop()
            fut = client.submit(
                kinds.task,
                campaign.kind,
                options,
                {k: v[idx] for k, v in cols.items()},
                words[idx],
                to,
                key=f"utrf-{campaign.kind}-{int(words[idx[0]]):016x}-{len(idx)}",
                retries=0,
            )
            by_future[fut] = idx
            fut.add_done_callback(finished.put)

    submit()
    while by_future:
        try:
            batch = [finished.get(timeout=TICK_S)]
        except queue.Empty:
            batch = []
        while not finished.empty():
            batch.append(finished.get())
        for fut in batch:
            idx = by_future.pop(fut)
            r = outcome(fut, cols, idx, words, store)
            prog.add_task(r)
            s.add_task(r)
        submit()
        if time.monotonic() - prog.last >= TICK_S:  # no call to the scheduler: one per worker
            prog.tick(min(len(by_future), n_workers))
    s.wall_s, s.driver_cpu_s = time.perf_counter() - start, time.process_time() - cpu0
    prog.tick(0, force=True)
    s.ok, s.failed = prog.ok, prog.failed
    return s
