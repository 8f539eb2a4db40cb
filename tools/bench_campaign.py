"""Benchmark of campaigns on Dask (``utrf.campaign``): the issue's goals, side by side.

    python -m tools.bench_campaign --update docs/benchmarks.md [--designs 1000000]

- Design sweep: ``--designs`` designs of the shipped design-sweep file (Latin hypercube) on a
  local cluster of the machine's cores, the whole command's work (sampling, keys, tasks,
  Parquet) timed from the cluster being up; and the CPU time one worker spends per design
  (``time.process_time`` around one 20,000-design task, so other jobs' load is not in it).
- Scaling: the same campaign of ``--scaling-designs`` designs on 1 worker, then on 2, runs
  an hour of each and their ratio; and a grasp campaign of ``--grasp-runs`` holds on the twin
  on 2 workers: the engine's share of the wall time (1 − the runs' own compute time over
  workers x wall).
- Per-task cost of the engine: ``--noop-tasks`` empty tasks through the same path.
- Dask's own CPU on an idle local cluster (2 workers), with its defaults and with the
  engine's ``LOCAL_CONFIG``.

The machine may be shared, so every campaign is also measured in CPU time (load does not
change it): the driver's process (the local scheduler runs in it) and every worker and nanny
process (psutil), from the cluster being up and warm to the last task's summary; against
the tasks' own CPU. From these, the scaling a 2-core machine with nothing else on it allows:
2 x (1 worker: the larger of the worker side's and the driver's CPU) / (2 workers: all CPU).
Then the largest cluster this design keeps busy, on paper, from Dask's documented per-task
overhead and the measured per-task and per-row figures. ``--update`` replaces the
"## Campaigns" section and leaves the other sections alone.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from tools.doc_sections import cpu_name, write_section
from utrf.campaign import engine, kinds, sampling, spec

COMMAND = "make bench-campaign  # python -m tools.bench_campaign --update docs/benchmarks.md"
REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "host" / "utrf" / "data" / "campaigns"
DASK_TASK_OVERHEAD_S = 1e-3  # distributed's docs: "each task suffers about 1ms of overhead"
LINK_BYTES_S = 125e6  # a 1 Gb/s link into the driver


def _design_file(tmp: Path, designs: int, chunk: int, name: str) -> Path:
    text = (EXAMPLES / "design-sweep.toml").read_text()
    text = text.replace("samples = 100000", f"samples = {designs}")
    text = text.replace('name = "finger-designs"', f'name = "{name}"\nchunk = {chunk}')
    path = tmp / f"{name}.toml"
    path.write_text(text)
    return path


def _quiet(_: str) -> None:
    return None


def design_cpu_per_design() -> float:
    """CPU seconds one worker spends per design (one 20,000-design task, in this process)."""
    c = spec.load(EXAMPLES / "design-sweep.toml")
    cols = sampling.columns(c)
    idx = np.arange(20_000)
    part = {k: v[idx] for k, v in cols.items()}
    keys = sampling.run_keys(part, engine.salt(c))
    kinds.table("design", {}, part, keys)  # warm up
    t0 = time.process_time()
    kinds.table("design", {}, part, keys)
    return (time.process_time() - t0) / len(idx)


class _Meter:
    """CPU of this process (driver and local scheduler) and of its children (workers,
    nannies): at the start, and at every progress line (the last: the last task's summary
    received, before the results are consolidated)."""

    def __init__(self) -> None:
        import psutil

        self.me = psutil.Process()
        self.kids = self.me.children(recursive=True)
        self.start = self.now = self.read()

    def read(self) -> tuple[float, float]:
        kids = 0.0
        for k in self.kids:
            try:
                t = k.cpu_times()
                kids += t.user + t.system
            except Exception:  # a worker restarted: its CPU so far is lost to the count
                pass
        t = self.me.cpu_times()
        return t.user + t.system, kids

    def progress(self, _: str) -> None:
        self.now = self.read()

    def figures(self) -> dict[str, float]:
        return {
            "driver_cpu_s": self.now[0] - self.start[0],
            "workers_cpu_s": self.now[1] - self.start[1],
        }


def measured(path: Path, out: Path, workers: int) -> dict[str, Any]:
    """One campaign on a local cluster made here (``engine.cluster``: the engine's own
    settings), warm before the meter starts; its summary, CPU and timeline figures."""
    c = spec.load(path)
    with engine.cluster(None, workers) as client:
        client.run(kinds.warm, c.kind)
        meter = _Meter()
        t0 = time.perf_counter()
        s = engine.run(c, out, address=client.scheduler.address, progress=meter.progress)
        command = time.perf_counter() - t0
    m = {**meter.figures(), **timeline(s)}
    # the driver's CPU while tasks ran; before (sampling, keys, what is done) apart
    m["prepare_cpu_s"] = m["driver_cpu_s"] - s.driver_cpu_s
    m["driver_cpu_s"] = s.driver_cpu_s
    cpu_all = m["driver_cpu_s"] + m["workers_cpu_s"]
    return {
        **m,
        "runs": s.ok + s.failed,
        "ok": s.ok,
        "failed": s.failed,
        "workers": s.workers,
        "wall_s": s.wall_s,
        "command_s": command,
        "overhead": s.overhead,
        "runs_per_h": 3600 * s.ok / s.wall_s,
        "task_cpu_s": s.task_cpu_s,
        "run_cpu_s": s.cpu_s,
        "busy_s": s.busy_s,
        "compute_s": s.compute_s,
        "engine_cpu_share": max(0.0, 1 - s.task_cpu_s / cpu_all) if cpu_all else 0.0,
        # on 2 idle cores: the worker side and the driver each need their CPU
        "bound_s": max(m["workers_cpu_s"], m["driver_cpu_s"]) if workers == 1 else cpu_all / 2,
    }


def timeline(s: engine.Summary) -> dict[str, float]:
    """Where the workers' wall time not in tasks went: before each worker's first task,
    between tasks, after each worker's last (shares of workers x wall)."""
    capacity = s.wall_s * max(s.workers, 1)
    end = s.started_at + s.wall_s
    by: dict[str, list[tuple[float, float]]] = {}
    for w, a, b in s.spans:
        by.setdefault(w, []).append((a, b))
    head = tail = 0.0
    for spans in by.values():
        spans.sort()
        head += max(0.0, spans[0][0] - s.started_at)
        tail += max(0.0, end - spans[-1][1])
    head += s.wall_s * max(0, s.workers - len(by))  # a worker that never ran a task
    gaps = max(0.0, capacity - s.busy_s - head - tail)
    return {k: v / capacity if capacity else 0.0 for k, v in
            {"head": head, "gaps": gaps, "tail": tail}.items()}  # fmt: skip


def run_design(tmp: Path, designs: int, chunk: int, workers: int, name: str) -> dict[str, Any]:
    m = measured(_design_file(tmp, designs, chunk, name), tmp / name, workers)
    size = sum(p.stat().st_size for p in (tmp / name / "runs").glob("*.parquet"))
    return {**m, "designs": designs, "parquet_bytes_per_row": size / max(m["ok"], 1)}


def run_grasp(tmp: Path, runs: int, workers: int) -> dict[str, Any]:
    path = tmp / f"grasp{workers}.toml"
    seeds = ", ".join(str(i) for i in range(runs))
    path.write_text(
        '[campaign]\nname = "bench-grasp"\nkind = "grasp"\n[sampler]\nmethod = "grid"\n'
        f'[parameters]\nobject = ["ball"]\nseed = [{seeds}]\nduration_s = 3.0\nhits = 1\n'
    )
    m = measured(path, tmp / f"grasp{workers}", workers)
    return {
        **m,
        "run_s": m["compute_s"] / max(m["ok"], 1),
        "run_cpu": m["run_cpu_s"] / max(m["ok"], 1),
    }


def grasp_pairs(
    tmp: Path, runs: int, repeats: int, threads: str | None = "1"
) -> list[dict[str, Any]] | None:
    """1 worker then 2, ``repeats`` times side by side: the pair of the median wall-clock
    ratio, with every pair's ratio (``ratios``) beside it. ``threads``: each run's twin
    threads on both sides (``UTRF_TWIN_THREADS``: the same work a run, the engine's scaling);
    None: the engine's own choice (a lone worker's twin on two threads, so that side does
    more than a worker's share of a core a run)."""
    if not runs or repeats < 1:
        return None
    pairs = []
    before = os.environ.pop(engine.TWIN_THREADS_ENV, None)
    try:
        if threads is not None:
            os.environ[engine.TWIN_THREADS_ENV] = threads
        for k in range(repeats):
            d = tmp / f"grasp-pair-{threads or 'default'}-{k}"
            d.mkdir()
            pairs.append((run_grasp(d, runs, 1), run_grasp(d, runs, 2)))
    finally:
        os.environ.pop(engine.TWIN_THREADS_ENV, None)
        if before is not None:
            os.environ[engine.TWIN_THREADS_ENV] = before
    pairs.sort(key=lambda p: p[1]["runs_per_h"] / p[0]["runs_per_h"])
    ratios = [g2["runs_per_h"] / g1["runs_per_h"] for g1, g2 in pairs]
    g1, g2 = pairs[len(pairs) // 2]
    return [{**g1, "ratios": ratios}, g2]


def idle_dask(seconds: float) -> dict[str, float]:
    """CPU of an idle local cluster of 2 workers over ``seconds``: Dask's defaults, then the
    engine's ``LOCAL_CONFIG`` (its profiler, ticks and monitors turned down)."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    out = {}
    for name, cfg in (("default", {}), ("engine", engine.LOCAL_CONFIG)):
        with (
            dask.config.set(cfg),
            LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1",
                         dashboard_address=None, silence_logs=logging.ERROR) as cluster,
            Client(cluster),
        ):  # fmt: skip
            time.sleep(1.0)
            meter = _Meter()
            time.sleep(seconds)
            meter.progress("")
            f = meter.figures()
            out[name] = (f["driver_cpu_s"] + f["workers_cpu_s"]) / seconds
    return out


def run_noop(tmp: Path, tasks: int) -> dict[str, Any]:
    path = tmp / "noop.toml"
    xs = ", ".join(f"{i}.0" for i in range(tasks))
    path.write_text(
        '[campaign]\nname = "noop"\nkind = "function"\n[sampler]\nmethod = "grid"\n'
        f'[parameters]\nx = [{xs}]\n[options]\nfunction = "tools.bench_campaign:noop"\n'
    )
    m = measured(path, tmp / "noop", 2)
    return {
        **m,
        "tasks": tasks,
        "per_task_s": m["wall_s"] / tasks,
        "driver_cpu_per_task_s": m["driver_cpu_s"] / tasks,
        "all_cpu_per_task_s": (m["driver_cpu_s"] + m["workers_cpu_s"]) / tasks,
    }


def noop(x: float) -> dict[str, float]:
    return {"x2": x}


def on_paper(m: dict[str, Any]) -> list[str]:
    """The largest cluster kept busy: workers x (1 / task time) tasks a second against what
    the scheduler and the driver take."""
    sched_rate = 1.0 / DASK_TASK_OVERHEAD_S
    driver_rate = 1.0 / m["noop"]["driver_cpu_per_task_s"]
    rate = min(sched_rate, driver_rate)
    run_s = m["grasp"][1]["run_cpu"] if m.get("grasp") else 15.0
    big = m["design"]
    tasks = math.ceil(big["designs"] / 20_000)
    chunk_s = big["task_cpu_s"] / tasks
    driver_per_chunk = big["driver_cpu_s"] / tasks
    return [
        f"- Dask documents about 1 ms of scheduler overhead a task ({sched_rate:.0f} tasks/s). "
        f"The driver's own CPU per task, measured with {m['noop']['tasks']} empty tasks, is "
        f"{m['noop']['driver_cpu_per_task_s'] * 1e3:.1f} ms ({driver_rate:.0f} tasks/s; the "
        "local cluster's scheduler runs in the driver's process, so this includes it).",
        f"- Grasp Monte Carlo: a twin run here costs {run_s:.1f} s of CPU (3 s holds); at "
        f"{rate:.0f} tasks/s the engine keeps about {rate * run_s:,.0f} single-threaded "
        "workers busy, forty times more for 120 s holds. What breaks first: the scheduler and "
        "the driver's one loop (Optuna's ask/tell for a search); results no longer pass "
        "through the driver.",
        f"- Design sweeps: a 20,000-design task is {chunk_s:.2f} s of a worker's CPU (its "
        f"Parquet part included, {big['parquet_bytes_per_row']:.0f} B a design, written by "
        f"the worker) and {driver_per_chunk * 1e3:.0f} ms of the driver's (sampling, keys, "
        f"sending the task's {big['designs'] and 20_000 * 8 * 9 / 1e6:.1f} MB of parameters "
        f"through the scheduler). The driver keeps about "
        f"{chunk_s / max(driver_per_chunk, 1e-9):.0f} workers busy. What breaks first: the "
        "driver's sampling and sending of parameters (remedy: tasks that draw their own "
        "samples), and a shared file system for the parts.",
    ]


def _pct(x: float) -> str:
    return f"{x * 100:.1f} %"


def section(m: dict[str, Any]) -> str:
    one, two = m["scaling"]
    big = m["design"]
    load = m["load"]
    lines = [
        "## Campaigns",
        "",
        f"`{COMMAND}`",
        "",
        f"Machine: {cpu_name()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
        f"load average {load[0]:.1f} / {load[1]:.1f} at the start and end (other jobs shared "
        "the cores: wall times are upper bounds; CPU times are not affected, and the "
        "2-idle-core figures come from them).",
        "",
        "| what | figure | goal |",
        "|---|---|---|",
        f"| {big['designs']:,} designs, 2 workers, from the cluster being up | "
        f"{big['wall_s']:.1f} s (the whole command {big['command_s']:.1f} s) | < 120 s |",
        f"| the same, CPU: workers (their tasks) / driver and scheduler (before the first "
        f"task: sampling, keys) | {big['workers_cpu_s']:.1f} s ({big['task_cpu_s']:.1f} s) / "
        f"{big['driver_cpu_s']:.1f} s ({big['prepare_cpu_s']:.1f} s): "
        f"**{big['bound_s'] + big['prepare_cpu_s']:.1f} s on 2 idle cores** | < 120 s |",
        f"| CPU per design in one task (20,000 designs) | {m['cpu_per_design_s'] * 1e6:.1f} us | |",
        f"| scaling, {one['designs']:,} designs (10,000 a task): 1 worker / 2 workers | "
        f"{one['runs_per_h']:,.0f} / {two['runs_per_h']:,.0f} runs/h: "
        f"{two['runs_per_h'] / one['runs_per_h']:.2f}x; from CPU, on 2 idle cores: "
        f"**{2 * one['bound_s'] / (2 * two['bound_s']):.2f}x** | >= 1.8x |",
        f"| engine and idle share of wall, design sweep (2 workers) | {_pct(big['overhead'])} "
        f"(before the first task {_pct(big['head'])}, between {_pct(big['gaps'])}, after the "
        f"last {_pct(big['tail'])}); of all CPU, outside tasks: "
        f"**{_pct(big['engine_cpu_share'])}** | <= 2 % |",
    ]
    if m.get("grasp"):
        g1, g2 = m["grasp"]
        lines += [
            f"| scaling, {g1['runs']} twin grasp holds (3 s), each run's twin on one thread "
            "on both sides (`UTRF_TWIN_THREADS=1`: the same work a run): 1 worker / 2 workers | "
            f"{g1['runs_per_h']:,.0f} / {g2['runs_per_h']:,.0f} runs/h: "
            f"**{g2['runs_per_h'] / g1['runs_per_h']:.2f}x** (the median of "
            f"{len(g1['ratios'])} pairs: {', '.join(f'{r:.2f}x' for r in g1['ratios'])}); "
            f"from CPU, on 2 idle cores: {one_two(g1, g2):.2f}x; cores the campaign kept "
            f"busy (all its CPU over wall): {_busy(g1):.2f} / {_busy(g2):.2f} | >= 1.8x |",
        ]
        if m.get("grasp_default"):
            d1, d2 = m["grasp_default"]
            lines.append(
                "| the same with the engine's own choice (a lone worker's twin on two "
                "threads, each of 2 workers' on one: the 1-worker side does more a run), one "
                f"pair | {d1['runs_per_h']:,.0f} / {d2['runs_per_h']:,.0f} runs/h: "
                f"{d2['runs_per_h'] / d1['runs_per_h']:.2f}x; a run's CPU {d1['run_cpu']:.2f} s "
                f"/ {d2['run_cpu']:.2f} s | |"
            )
        lines += [
            f"| a twin run's CPU, 1 worker / 2 workers | {g1['run_cpu']:.2f} s / "
            f"{g2['run_cpu']:.2f} s | |",
            f"| the engine's own share of wall, {g2['runs']} twin grasp holds (2 workers): "
            "before each worker's first task and between tasks | "
            f"**{_pct(g2['head'] + g2['gaps'])}** (before {_pct(g2['head'])}, between "
            f"{_pct(g2['gaps'])}); of all CPU, outside tasks: {_pct(g2['engine_cpu_share'])} "
            "| <= 2 % |",
            f"| the campaign's imbalance: a worker idle after its last task while the other "
            f"ends its own | {_pct(g2['tail'])} (all idle and engine: {_pct(g2['overhead'])}; "
            f"{g2['wall_s']:.1f} s wall, {g2['run_s']:.1f} s a run) | |",
        ]
    idle = m["idle"]
    lines += [
        f"| engine per task, {m['noop']['tasks']} empty tasks: wall / CPU (all processes) | "
        f"{m['noop']['per_task_s'] * 1e3:.2f} ms / {m['noop']['all_cpu_per_task_s'] * 1e3:.2f} "
        "ms | |",
        f"| an idle local cluster of 2 workers: Dask's defaults / the engine's settings | "
        f"{idle['default'] * 100:.1f} % / {idle['engine'] * 100:.1f} % of a core | |",
        "",
        "The engine's share of wall counts everything that is not a task on a worker (a task "
        "is its runs and writing their Parquet part): Dask, the driver, and workers idle "
        "before their first task and after their last (1 − Σ task time / (workers x wall)). "
        "Cluster start-up (spawning the worker processes, and each worker importing what the "
        "runs use) is outside it. The CPU share is the same question asked of CPU time: all "
        "the processes' CPU (driver, scheduler, workers, nannies) not spent in tasks. The "
        "2-idle-core figures: with 1 worker, the worker side and the driver each have a core "
        "(the larger of their CPU times); with 2, every process shares the two cores (all "
        "the CPU over 2). The goal's figure (the engine's own share) is what Dask and the "
        "driver cost the workers: before each one's first task and between its tasks; the "
        "time a worker waits after its last task for the other to end its own is the "
        "campaign's granularity (12 runs of a few seconds on 2 workers), not the engine's, "
        "and is shown apart. On a machine shared with other sessions, Linux's autogroup "
        "scheduling shares the cores between sessions, not between processes: a campaign "
        "that keeps fewer than 2 cores busy with 2 workers (the figure above) measures its "
        "session's share, not the engine's scaling; the CPU figures do not depend on it.",
        "",
        "On paper (Dask's documented limit and the figures above):",
        "",
        *on_paper(m),
        "",
    ]
    return "\n".join(lines)


def _busy(g: dict[str, Any]) -> float:
    """Cores a campaign kept busy: all its processes' CPU over its wall time (under 2 with 2
    workers: the machine gave it less, e.g. other sessions' share under autogroup)."""
    return (g["driver_cpu_s"] + g["workers_cpu_s"]) / g["wall_s"] if g["wall_s"] else 0.0


def one_two(g1: dict[str, Any], g2: dict[str, Any]) -> float:
    """2-worker over 1-worker runs an hour on 2 idle cores, from CPU per run."""
    return (g1["bound_s"] / max(g1["ok"], 1)) / (g2["bound_s"] / max(g2["ok"], 1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=COMMAND, description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--designs", type=int, default=1_000_000)
    parser.add_argument("--scaling-designs", type=int, default=200_000)
    # not 4: one run's spread of time then left a worker idle after its last task, a share
    # that measured the campaign's size more than the engine (docs/benchmarks.md)
    parser.add_argument("--grasp-runs", type=int, default=12)
    # one pair's wall-clock ratio varies widely between pairs, even on a quiet machine
    parser.add_argument("--grasp-repeats", type=int, default=3)
    parser.add_argument("--noop-tasks", type=int, default=200)
    parser.add_argument("--idle-s", type=float, default=10.0)
    parser.add_argument("--update", type=Path, help="write the section into this Markdown file")
    parser.add_argument("--json", type=Path, help="the figures as JSON")
    args = parser.parse_args(argv)
    m: dict[str, Any] = {"load": [os.getloadavg()[0]]}
    m["cpu_per_design_s"] = design_cpu_per_design()
    with tempfile.TemporaryDirectory(prefix="utrf-bench-campaign-") as tmp:
        t = Path(tmp)
        m["idle"] = idle_dask(args.idle_s)
        m["scaling"] = [
            run_design(t, args.scaling_designs, 10_000, 1, "scale1"),
            run_design(t, args.scaling_designs, 10_000, 2, "scale2"),
        ]
        m["design"] = run_design(t, args.designs, 20_000, 2, "million")
        m["noop"] = run_noop(t, args.noop_tasks)
        m["grasp"] = grasp_pairs(t, args.grasp_runs, args.grasp_repeats)
        m["grasp_default"] = grasp_pairs(t, args.grasp_runs, 1, None)
    m["load"].append(os.getloadavg()[0])
    text = section(m)
    print(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(m, indent=2) + "\n")
    if args.update:
        write_section(args.update, text, "## Campaigns")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
