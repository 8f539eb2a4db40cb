"""``make bench-twin``: the twin's throughput against a reference commit, side by side.

A 120 s plain grasp hold (``utrf hil grasp-hold --emulated --duration-s 120``, a fresh process
each time) of this checkout and of a reference commit (f500c49 by default: the twin before
issue 20), run alternately on the same machine, several repeats; the ratio of the medians is
the figure (absolute times differ twofold between this project's machines, and the machine
may be shared). Each engine alone too, in each tree: the ELF on simavr with no plant (the
same host traffic, the encoders held still), and the MJCF stepped alone; the rest of the
hold's time is Python and the crossings between them.

The reference is a throwaway ``git worktree`` under ``build/`` (never committed), built with
its own ``make firmware emulator`` and run with its own sources (``PYTHONPATH``, working
directory), this checkout's Python environment. Prints a Markdown section and writes it into
docs/benchmarks.md between the twin markers (``--no-update``: only prints).

``python -m tools.bench_twin --engine elf|mjcf --seconds S`` runs one engine alone and prints
JSON (what the benchmark runs in each tree: it uses only interfaces both trees have).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import date
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
BENCH_DOC = REPO_ROOT / "docs" / "benchmarks.md"
BEGIN = "<!-- BEGIN twin (make bench-twin) -->"
END = "<!-- END twin -->"
REFERENCE = "f500c49"


# --- one engine alone (runs inside either tree) ----------------------------------------------


@contextmanager
def elf_alone(elf: str | Path | None = None) -> Iterator[tuple[Any, Any]]:
    """The firmware on simavr with no plant, under the hold's host traffic (telemetry at 100 Hz,
    heartbeats), five fingers in POSITION at the angles their still encoders read: the board
    and its ``SimLink``. ``elf`` None: the tree's own build. Also tools/fw_profile.py's."""
    from utrf.emulator import EmulatedBoard
    from utrf.hand.simlink import SimLink
    from utrf.hil.rig import EmulatedTruth
    from utrf.protocol import messages as m

    params = EmulatedTruth(actuator=None).plant_params()
    with EmulatedBoard(elf, realtime=False, seed=0, plant_params=params) as board:
        board._native.attach_plant(None)  # no plant: the encoder voltages stay as they are
        latest: list = [None]

        def keep(t) -> None:
            if isinstance(t.message, m.State):
                latest[0] = t.message

        link = SimLink(board, on_telemetry=keep)
        link.handshake()
        link.request(m.SetTelemetry(rate_hz=100))
        link.sleep(0.1)
        theta = tuple(latest[0].theta2)
        link.request(m.ClearFaults(mask=0b11111))
        link.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=0b11111, value=theta))
        link.request(
            m.SetMode(
                mask=0b11111,
                mode=(m.ControlMode.POSITION,) * 5,
                duty=(0.0,) * 5,
                effort=(0.0,) * 5,
            )
        )
        yield board, link


def engine_elf(seconds: float) -> dict:
    """The firmware on simavr with no plant, the hold's host traffic held still (elf_alone)."""
    from utrf.protocol import messages as m

    with elf_alone() as (board, link):
        cpu0, wall0, sim0 = time.process_time(), time.perf_counter(), board.sim_time
        link.sleep(seconds)
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        sim = board.sim_time - sim0
        modes = link.request(m.GetStatus()).mode
    return {"sim": sim, "cpu": cpu, "wall": wall,
            "held": all(x == m.ControlMode.POSITION for x in modes)}  # fmt: skip


def engine_mjcf(seconds: float) -> dict:
    """The twin's MuJoCo hand stepped alone (no MCU, no motor model): ``seconds`` of its
    0.5 ms steps in one call, the fingers at the grasp pose's contact angles, motors off."""
    import mujoco

    from utrf.emulator.mujoco_plant import MujocoPlant
    from utrf.hil.rig import EmulatedTruth

    plant = MujocoPlant(None, EmulatedTruth(actuator=None).plant_params(), 0, timestep=1e-3)
    for f, theta2 in enumerate((0.3, 0.6, 0.6, 0.6, 0.6)):
        plant.set_theta2(f, theta2)
    steps = round(seconds / plant.model.opt.timestep)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    mujoco.mj_step(plant.model, plant.data, nstep=steps)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    return {"sim": steps * plant.model.opt.timestep, "cpu": cpu, "wall": wall}


def _thread_clocks() -> dict[str, float]:
    """CPU seconds of this process's threads now, by name (the harness names its own:
    ``utrf-board``, the run ahead; ``utrf-plant``, the plant's), the main thread as ``client``."""
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[str, float] = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            stat = Path(f"/proc/self/task/{tid}/stat").read_text()
            name = Path(f"/proc/self/task/{tid}/comm").read_text().strip()
        except OSError:  # ended meanwhile
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        name = "client" if int(tid) == os.getpid() else name
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def engine_threads(seconds: float) -> dict:
    """The hold in this process: each thread's CPU taken as the board closes, and how many
    periods the MCU's thread stepped the plant itself (two twin threads; this checkout's)."""
    from utrf.cli import main as cli
    from utrf.emulator import board as emulated

    seen: dict = {}
    close = emulated.EmulatedBoard.close

    def taking(self: Any, *args: Any, **kwargs: Any) -> Any:
        if not seen:
            seen["threads"] = _thread_clocks()
            seen["wall"] = time.perf_counter() - wall0
            seen["inline"] = getattr(self._native, "plant_inline_periods", None)
            seen["wait"] = getattr(self._native, "plant_wait_s", None)
            seen["periods"] = round(self.sim_time / self.exchange_period)
            seen["twin_threads"] = self.plant_threads
        return close(self, *args, **kwargs)

    runs = {"ahead": 0, "stops": 0}  # the board's runs ahead of the client, the stops in them
    ahead, batch = emulated.EmulatedBoard.run_ahead, emulated.EmulatedBoard.run_ahead_stops

    def counted_ahead(self: Any, *args: Any, **kwargs: Any) -> Any:
        runs["ahead"] += 1
        runs["stops"] += 1
        return ahead(self, *args, **kwargs)

    def counted_batch(self: Any, targets: Any, *args: Any, **kwargs: Any) -> Any:
        runs["ahead"] += 1
        runs["stops"] += len(targets)
        return batch(self, targets, *args, **kwargs)

    emulated.EmulatedBoard.close = taking  # type: ignore[method-assign]
    emulated.EmulatedBoard.run_ahead = counted_ahead  # type: ignore[method-assign]
    emulated.EmulatedBoard.run_ahead_stops = counted_batch  # type: ignore[method-assign]
    out = Path(tempfile.mkdtemp(prefix="bench-twin-"))
    wall0 = time.perf_counter()
    try:
        rc = cli(["hil", "grasp-hold", "--emulated", "--duration-s", f"{seconds:g}",
                  "--out", str(out / "run"), "--quiet"])  # fmt: skip
    finally:
        emulated.EmulatedBoard.close = close  # type: ignore[method-assign]
        emulated.EmulatedBoard.run_ahead = ahead  # type: ignore[method-assign]
        emulated.EmulatedBoard.run_ahead_stops = batch  # type: ignore[method-assign]
        shutil.rmtree(out, ignore_errors=True)
    seen["runs_ahead"], seen["samples"] = runs["ahead"], runs["stops"]
    if not seen or rc not in (0, 1):  # 1: the hold ran and reported
        raise RuntimeError(f"the hold by thread did not run (exit {rc})")
    return seen


# --- the benchmark (drives both trees) -------------------------------------------------------


def reference_tree(commit: str) -> Path:
    """A worktree of ``commit`` under build/, built with its own make (reused when there)."""
    tree = REPO_ROOT / "build" / f"ref-{commit}"
    if not (tree / ".git").exists():
        # a build/ removed since (make clean) leaves its worktree registered: forget it first
        subprocess.run(["git", "worktree", "prune"], cwd=REPO_ROOT, check=True)
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(tree), commit], cwd=REPO_ROOT, check=True
        )
    venv = Path(sys.prefix)
    subprocess.run(
        ["make", "-s", "-C", str(tree), f"VENV={venv}", "firmware", "emulator"], check=True
    )
    return tree


def _env(tree: Path, threads: int | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree / "host")
    env.pop("UTRF_SIM_LIB", None)  # each tree's own harness, from its build/
    env.pop("UTRF_TWIN_THREADS", None)  # the tree's own choice, unless asked
    if threads is not None:
        env["UTRF_TWIN_THREADS"] = str(threads)
    return env


def _child(
    cmd: list[str], tree: Path, threads: int | None = None
) -> tuple[float, float, subprocess.CompletedProcess]:
    """Run ``cmd`` in ``tree``: wall seconds, CPU seconds (the child's user + system)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=tree, env=_env(tree, threads), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    if done.returncode not in (0, 1):  # 1: the hold ran and reported (not all held, a fault)
        tail = "\n".join((done.stderr or done.stdout).strip().splitlines()[-5:])
        raise RuntimeError(f"{' '.join(cmd)} in {tree} failed ({done.returncode}):\n{tail}")
    return wall, cpu, done


def hold(tree: Path, seconds: float, threads: int | None = None) -> dict:
    """The grasp hold, a fresh process: wall and CPU seconds (``threads``: the twin's, through
    UTRF_TWIN_THREADS; None: the tree's own choice)."""
    out = Path(tempfile.mkdtemp(prefix="bench-twin-"))
    try:
        cmd = [sys.executable, "-m", "utrf", "hil", "grasp-hold", "--emulated",
               "--duration-s", f"{seconds:g}", "--out", str(out / "run"), "--quiet"]  # fmt: skip
        wall, cpu, done = _child(cmd, tree, threads)
        results = json.loads((out / "run" / "results.json").read_text())
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return {"wall": wall, "cpu": cpu, "rc": done.returncode,
            "complete": bool(results.get("complete")), "load": os.getloadavg()[0]}  # fmt: skip


def engine(tree: Path, which: str, seconds: float, threads: int | None = None) -> dict:
    """One engine alone in ``tree`` (this file run there with that tree's sources)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--engine", which,
           "--seconds", f"{seconds:g}"]  # fmt: skip
    _, _, done = _child(cmd, tree, threads)
    return json.loads(done.stdout.strip().splitlines()[-1])


def median(rows: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in rows)


def _by_thread(th: dict) -> str:
    """A by-thread run's cell: each thread's CPU, and with two twin threads what the
    hand-overs cost the MCU's thread (its wait for the plant's, the periods it stepped the
    plant itself)."""
    clocks = dict(th["threads"])
    parts = [clocks.pop(k, 0.0) for k in ("client", "utrf-board", "utrf-plant")]
    cell = " / ".join(f"{x:.1f} s" for x in (*parts, sum(clocks.values())))
    if th.get("inline") is not None and th["twin_threads"] == 2:
        share = 100 * th["inline"] / max(th["periods"], 1)
        cell += f"; the MCU's thread stepped the plant itself in {share:.0f} % of the periods"
        if th.get("wait") is not None:
            cell += f" and waited {th['wait']:.1f} s for the plant's thread at the others"
    if th.get("runs_ahead"):
        cell += (
            f"; the board ran ahead of the client {th['runs_ahead']} times through its "
            f"{th['samples']} samples ({th['samples'] / th['runs_ahead']:.1f} a run)"
        )
    return cell


def report(
    ref: str, runs: dict[str, list[dict]], alone: dict, seconds: float, repeats: int, threads: int
) -> str:
    """The section; ``threads``: the checkout's own twin thread count (``runs["new"]``), the
    other count's runs being ``runs["other"]``."""
    from tools.doc_sections import cpu_name

    new, old, one = runs["new"], runs["ref"], runs["other"]
    ratio_wall = median(new, "wall") / median(old, "wall")
    ratio_cpu = median(new, "cpu") / median(old, "cpu")

    def paired(key: str) -> str:  # each run against the other tree's run beside it
        each = [a[key] / b[key] for a, b in zip(new, old, strict=True)]
        return f"median {statistics.median(each):.2f} ({', '.join(f'{x:.2f}' for x in each)})"

    loads = [r["load"] for r in new + old + one]

    def cell(rows: list[dict], key: str) -> str:
        each = ", ".join(f"{r[key]:.1f}" for r in rows)
        return f"**{median(rows, key):.1f} s** ({each})"

    def engines(tag: str) -> str:  # this checkout's one-thread hold: no spinning counted
        e, j = alone[tag]["elf"], alone[tag]["mjcf"]
        h = median(runs["other" if tag == "new" and threads == 2 else tag], "cpu")
        rest = h - e["cpu"] - j["cpu"]
        shares = " / ".join(f"{100 * x / h:.0f}" for x in (e["cpu"], j["cpu"], rest))
        return f"{e['cpu']:.1f} s / {j['cpu']:.1f} s / {rest:.1f} s ({shares} %)"

    rows = [alone[k] for k in ("threads", "threads_other") if k in alone]

    lines = [
        BEGIN,
        "## Twin throughput (issue 20)",
        "",
        f"Measured with `make bench-twin` (`python -m tools.bench_twin`) on {cpu_name()}, "
        f"{os.cpu_count()} cores, {date.today().isoformat()}: `utrf hil grasp-hold --emulated "
        f"--duration-s {seconds:g}` (the plain hold: grasp-bottle, 100 Hz telemetry, hits), a "
        f"fresh process each time (each tree's bytecode compiled beforehand, as an installed "
        f"package's is), this checkout (its twin on {threads} thread{'s' if threads > 1 else ''}"
        ", its own "
        "choice: `utrf.emulator.twin_threads`; the board running ahead of the client on a "
        "thread of its own) against "
        f"`{ref}` (a `git worktree` of it under "
        f"`build/`, built by its own make), alternately, {repeats} times each; medians. CPU "
        "time is the process's user + system time; the machine was shared (load average "
        f"{min(loads):.1f}–{max(loads):.1f} during the runs), which moves wall time more than "
        "CPU time.",
        "",
        f"| | this checkout | `{ref}` | ratio of the medians; of each pair run side by side |",
        "|---|---|---|---|",
        f"| wall time | {cell(new, 'wall')} | {cell(old, 'wall')} | **{ratio_wall:.2f}**; "
        f"pairs: {paired('wall')} |",
        f"| CPU time | {cell(new, 'cpu')} | {cell(old, 'cpu')} | **{ratio_cpu:.2f}**; "
        f"pairs: {paired('cpu')} |",
        f"| CPU / wall (cores kept busy) | {median(new, 'cpu') / median(new, 'wall'):.2f} | "
        f"{median(old, 'cpu') / median(old, 'wall'):.2f} | |",
        f"| this checkout, the twin on {3 - threads} thread{'s' if threads == 1 else ''} "
        f"(`UTRF_TWIN_THREADS={3 - threads}`): wall / CPU | "
        f"{cell(one, 'wall')} / {cell(one, 'cpu')} | | wall **"
        f"{median(one, 'wall') / median(old, 'wall'):.2f}**, CPU **"
        f"{median(one, 'cpu') / median(old, 'cpu'):.2f}** of `{ref}`'s |",
        f"| each engine alone, CPU: the ELF on simavr with no plant / the MJCF stepped alone / "
        f"the rest of the hold (Python, start-up, the figure, the crossings; this checkout's: "
        f"of its one-thread hold) | {engines('new')} "
        f"| {engines('ref')} | |",
        *(
            f"| this checkout's hold by thread, CPU (one more run, in-process: each thread's "
            f"clock as the board closes, {th['wall']:.1f} s in; the twin on {th['twin_threads']} "
            f"thread{'s' if th['twin_threads'] > 1 else ''}): the client (Python) / the board's "
            f"(the MCU, and the plant where stepped there) / the plant's / the rest | "
            f"{_by_thread(th)} | | |"
            for th in rows
        ),
        "",
        f"The ELF alone: the firmware for {seconds:g} s simulated with no plant attached, the "
        "hold's host traffic (telemetry at 100 Hz, heartbeats), five fingers in POSITION at the "
        "angles their still encoders read. The MJCF alone: the twin's hand model (plain, no "
        f"object) stepped {seconds:g} s in its 0.5 ms steps in one `mj_step(nstep=...)` call, "
        "the motors off.",
        END,
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--engine",
        choices=("elf", "mjcf", "threads"),
        help="run one engine alone (threads: the hold, each thread's CPU); JSON out",
    )
    p.add_argument("--seconds", type=float, default=120.0, help="simulated seconds")
    p.add_argument("--repeats", type=int, default=3, help="holds per tree, alternating")
    p.add_argument("--reference", default=REFERENCE, help="the commit to compare with")
    p.add_argument("--no-update", action="store_true", help="print only")
    args = p.parse_args(argv)
    if args.engine:
        fn = {"elf": engine_elf, "mjcf": engine_mjcf, "threads": engine_threads}[args.engine]
        print(json.dumps(fn(args.seconds)))
        return 0
    if args.repeats < 1 or not args.seconds > 0:
        p.error("--repeats must be >= 1 and --seconds > 0")
    trees = {"new": REPO_ROOT, "ref": reference_tree(args.reference)}
    for tree in trees.values():  # as installed: bytecode compiled once, not at every start
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(tree / "host")], check=True)
    from utrf.emulator.twin_threads import plant_threads

    own = plant_threads()
    other = 3 - own  # the checkout's twin on the other thread count beside it
    runs: dict[str, list[dict]] = {"new": [], "ref": [], "other": []}
    for i in range(args.repeats):
        for tag in ("new", "ref", "other") if i % 2 == 0 else ("other", "ref", "new"):
            tree, threads = (trees["new"], other) if tag == "other" else (trees[tag], None)
            runs[tag].append(hold(tree, args.seconds, threads))
            print(f"{tag} {runs[tag][-1]}", file=sys.stderr, flush=True)
    alone = {
        tag: {which: engine(trees[tag], which, args.seconds) for which in ("elf", "mjcf")}
        for tag in ("new", "ref")
    }
    for n in (own, other):  # by thread, the checkout's own count first
        alone["threads" if n == own else "threads_other"] = engine(
            trees["new"], "threads", args.seconds, n
        )
    print(json.dumps(alone), file=sys.stderr)
    section = report(args.reference, runs, alone, args.seconds, args.repeats, own)
    print(section)
    if not args.no_update:
        from tools.doc_sections import write_section

        write_section(BENCH_DOC, section, BEGIN, END)
        print(f"\nwritten to {BENCH_DOC}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
