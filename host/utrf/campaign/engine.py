"""Running a campaign on Dask (distributed): the runs not yet done, as tasks, on a cluster.

Local by default: a ``LocalCluster`` of one single-threaded worker process per core, made
and closed here (no set-up). ``address``: a scheduler the user already runs (``dask
scheduler`` / ``dask worker``, or any deployment). Dask schedules, balances and, when a
worker dies, runs its tasks again on another; this module keeps a window of tasks submitted,
writes each result as it comes (``Store``), and says how far it is. Nothing here queues,
schedules or pools work of its own.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from utrf.campaign import kinds, sampling
from utrf.campaign.sampling import Columns
from utrf.campaign.spec import Campaign, CampaignError
from utrf.campaign.store import Store, columns_table

ProgressFn = Callable[[str], None]
FLUSH_S = 2.0  # results reach the disk at least this often
TICK_S = 1.0  # progress at most this often


@dataclass
class Summary:
    total: int  # runs in the campaign
    skipped: int  # already done before this invocation
    ok: int
    failed: int
    wall_s: float  # from the first task submitted to the last result written
    busy_s: float  # the runs' own compute time, summed over workers
    workers: int
    startup_s: float  # making (or reaching) the cluster
    cpu_s: float = 0.0  # the runs' CPU time, summed over workers

    @property
    def overhead(self) -> float:
        """The share of the workers' wall time not spent in runs (the engine's, the
        driver's and idle time at the end)."""
        capacity = self.wall_s * max(self.workers, 1)
        return max(0.0, 1.0 - self.busy_s / capacity) if capacity > 0 else 0.0

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
    n = workers or os.cpu_count() or 1
    with (
        LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            silence_logs=logging.ERROR,
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


def _table(cols: Columns) -> pa.Table:
    return columns_table(cols)


def _failed(cols: Columns, keys: np.ndarray, reason: str) -> Columns:
    n = len(keys)
    return {
        "run_key": keys,
        "worker": np.full(n, ""),
        "status": np.full(n, "failed"),
        "error": np.full(n, reason, dtype=object),
        "compute_s": np.zeros(n),
        "cpu_s": np.zeros(n),
        **cols,
    }


def running(client: Any) -> int:
    """Runs executing now: tasks the scheduler has placed, at most a thread's worth each
    (a worker also holds the next one or two it will run)."""
    threads = client.nthreads()
    return sum(min(len(keys), threads.get(w, 1)) for w, keys in client.processing().items())


def salt(campaign: Campaign) -> str:
    return f"{campaign.kind}|{campaign.digest}"


def run(
    campaign: Campaign,
    out: Path,
    *,
    address: str | None = None,
    workers: int | None = None,
    progress: ProgressFn = print,
) -> Summary:
    """Run every run of ``campaign`` not already in ``out``; write each as it comes."""
    kind = kinds.get(campaign.kind)
    kind.check(campaign)
    store = Store(out)
    store.claim(campaign)
    if campaign.method == "optuna":
        from utrf.campaign import search

        return search.run(campaign, store, address=address, workers=workers, progress=progress)
    cols = sampling.columns(campaign)
    keys = sampling.run_keys(cols, salt(campaign))
    _, first = np.unique(keys, return_index=True)  # a grid listing a value twice runs it once
    done = store.done_keys()
    todo = np.sort(first[~np.isin(keys[first], list(done))])
    total = len(first)
    chunk = campaign.chunk or kind.chunk
    tasks = [todo[i : i + chunk] for i in range(0, len(todo), chunk)]
    if not tasks:  # everything is done: no cluster to start
        progress(f"done {total}/{total} ({total} from before)")
        store.consolidate()
        return Summary(total, total, 0, 0, 0.0, 0.0, 0, 0.0)
    t0 = time.monotonic()
    with cluster(address, workers) as client:
        startup = time.monotonic() - t0
        n_workers = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
        summary = _drive(
            client,
            campaign,
            cols,
            keys,
            tasks,
            store,
            total,
            total - len(todo),
            n_workers,
            progress,
        )
    summary.startup_s = startup
    store.consolidate()
    return summary


def _drive(
    client: Any,
    campaign: Campaign,
    cols: Columns,
    keys: np.ndarray,
    tasks: list[np.ndarray],
    store: Store,
    total: int,
    skipped: int,
    n_workers: int,
    progress: ProgressFn,
) -> Summary:
    from distributed import as_completed

    prog = _Progress(total, skipped, progress)
    window = 2 * n_workers  # enough queued that no worker waits for the driver
    queue = list(reversed(tasks))
    by_future: dict[Any, np.ndarray] = {}
    buffer: list[pa.Table] = []
    last_flush = time.monotonic()
    busy = cpu = 0.0
    start = time.perf_counter()
    ac = as_completed()

    options = {**campaign.options, "firmware_paths": campaign.firmware}

    def submit() -> None:
        while queue and len(by_future) < window:
            idx = queue.pop()
            part = {k: v[idx] for k, v in cols.items()}
            fut = client.submit(
                kinds.execute,
                campaign.kind,
                options,
                part,
                keys[idx],
                key=f"utrf-{campaign.kind}-{keys[idx[0]]}-{len(idx)}",
                retries=0,
            )
            by_future[fut] = idx
            ac.add(fut)

    submit()
    while by_future:
        batch = ac.next_batch(block=False) if ac.has_ready() else []
        if not batch:
            time.sleep(0.02)
        for fut in batch:
            idx = by_future.pop(fut)
            if fut.status == "finished":
                result = fut.result()
            else:  # the task itself died (a worker lost too often): its runs failed
                exc = fut.exception()
                part = {k: v[idx] for k, v in cols.items()}
                result = _table(_failed(part, keys[idx], f"{type(exc).__name__}: {exc}"))
            fut.release()
            ok = pc.sum(pc.equal(result.column("status"), "ok")).as_py() or 0
            prog.ok += ok
            prog.failed += result.num_rows - ok
            busy += pc.sum(result.column("compute_s")).as_py() or 0.0
            cpu += pc.sum(result.column("cpu_s")).as_py() or 0.0
            buffer.append(result)
        submit()
        if buffer and (time.monotonic() - last_flush >= FLUSH_S or not by_future):
            store.append(pa.concat_tables(buffer, promote_options="default"))
            buffer, last_flush = [], time.monotonic()
        if time.monotonic() - prog.last >= TICK_S:
            prog.tick(running(client))
    prog.tick(0, force=True)
    return Summary(
        total, skipped, prog.ok, prog.failed, time.perf_counter() - start, busy, n_workers, 0.0, cpu
    )
