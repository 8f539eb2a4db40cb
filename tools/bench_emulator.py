"""``make bench-emulator``: the emulated board's real-time factor, and the firmware's control
tick's CPU load measured in simavr cycles (0 to 5 fingers under position control, telemetry on).

Prints a Markdown section and writes it into docs/benchmarks.md between the emulator markers
(the rest of that file is left alone). ``--no-update`` only prints.

The tick is timed from the timer-2 compare interrupt's entry to its RETI through simavr's
interrupt signals: no change to the firmware. "Exclusive" leaves out the UART and ADC
interrupts that nest inside it (the firmware re-enables interrupts during its tick).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

from tools.doc_sections import cpu_name, write_section
from utrf.emulator import DEFAULT_ELF, BoardProcess, EmulatedBoard
from utrf.hand.simlink import SimLink
from utrf.protocol import Link
from utrf.protocol import messages as m

REPO_ROOT = Path(__file__).resolve().parents[1]
BENCH_DOC = REPO_ROOT / "docs" / "benchmarks.md"
BEGIN = "<!-- BEGIN emulator (make bench-emulator) -->"
END = "<!-- END emulator -->"
PERIOD_CYCLES = 16_000  # 1 kHz tick at 16 MHz
ALL = 0b11111


def served_apart(elf: Path, seconds: float) -> dict:
    """The same client load with the board in a process of its own (BoardProcess)."""
    with BoardProcess(elf, pty=False) as board:
        with Link.open(board.url) as link:
            link.handshake()
            start_position_control(link.request, 0.0)
            link.request(m.SetTelemetry(rate_hz=500))
            end = time.perf_counter() + seconds
            while time.perf_counter() < end:
                targets = targets_at(time.perf_counter())
                link.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=targets))
                time.sleep(0.05)
            lost = link.stats().stream_lost
        final = board.close()
    assert final is not None
    return {"rtf": final["realtime_factor"], "capacity": final["capacity"], "stream_lost": lost}


def targets_at(t: float) -> tuple[float, ...]:
    """Five Joint-2 targets sweeping 0.3..1.3 rad, out of phase: every PID stays busy."""
    return tuple(0.8 + 0.5 * math.sin(2 * math.pi * 0.5 * t + 1.2 * f) for f in range(5))


def start_position_control(request, t: float, fingers: int = 5) -> None:
    """Clear faults, set the sweeping targets, and put the first ``fingers`` in POSITION."""
    request(m.ClearFaults(mask=ALL))
    request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=targets_at(t)))
    mask = (1 << fingers) - 1
    if mask:
        request(
            m.SetMode(
                mask=mask,
                mode=(m.ControlMode.POSITION,) * 5,
                duty=(0.0,) * 5,
                effort=(0.0,) * 5,
            )
        )


class Timed:
    """Wraps a callable and adds up the wall time spent in it."""

    def __init__(self, fn) -> None:
        self.fn = fn
        self.seconds = 0.0

    def __call__(self, *args):
        t0 = time.perf_counter()
        try:
            return self.fn(*args)
        finally:
            self.seconds += time.perf_counter() - t0


def driven(elf: Path, seconds: float, telemetry_hz: int) -> dict:
    """Five fingers tracking moving targets, simulated as fast as the machine goes, over the
    engine's client (SimLink): the board and its plant run in C between the link's looks at
    the output (at each frame the board sends, and for heartbeats)."""
    with EmulatedBoard(elf, realtime=False) as board:  # the MuJoCo hand, 1 ms exchanges
        states = [0]

        def count(t) -> None:
            states[0] += isinstance(t.message, m.State)

        link = SimLink(board, on_telemetry=count)
        link.handshake()
        start_position_control(link.request, board.sim_time)
        link.request(m.SetTelemetry(rate_hz=telemetry_hz))
        link.request(m.ResetStats())
        link.sleep(0.1)
        native = board._native  # timing its part: simavr and the plant, in C
        in_c = Timed(native.run_plant)
        native.run_plant = in_c
        in_c_until = Timed(native.run_plant_until)
        native.run_plant_until = in_c_until
        states[0] = 0
        slept0 = board.stats["sleep_cycles"]
        load0 = os.getloadavg()[0]
        sim0, wall0, cpu0 = board.sim_time, time.perf_counter(), time.process_time()
        while board.sim_time - sim0 < seconds:
            link.request(
                m.SetTargets(
                    kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=targets_at(board.sim_time)
                )
            )
            link.sleep(0.05)
        wall = time.perf_counter() - wall0
        cpu = time.process_time() - cpu0
        sim = board.sim_time - sim0
        slept = board.stats["sleep_cycles"] - slept0
        fw = link.request(m.GetStats())
        state = link.request(m.GetState())
        error = np.abs(np.array(state.theta2) - np.array(state.target)).max()
        return {
            "sim": sim,
            "wall": wall,
            "rtf": sim / wall,
            "cycles_per_s": sim * 16e6 / wall,
            "cpu_rtf": sim / cpu,
            "c_share": (in_c.seconds + in_c_until.seconds) / wall,
            "c_per_sim": (in_c.seconds + in_c_until.seconds) / sim,
            "load": max(load0, os.getloadavg()[0]),
            "awake": 1.0 - slept / (sim * 16e6),
            "fw": fw,
            "faults": link.request(m.GetStatus()).faults,
            "telemetry_rate": states[0] / sim,
            "tracking_error": float(error),
        }


def grasp_hold_wall(seconds: float, obj: str | None = None, elf: Path | None = None) -> dict:
    """``utrf hil grasp-hold --emulated --duration-s SECONDS`` as a user runs it (a fresh
    process: start-up, imports and the figure included): its wall and CPU time, and the load
    average around it. ``obj``: the object hold on the MuJoCo hand (``--object OBJ``, its
    rendered picture included). ``elf``: the firmware (None: the CLI's default)."""
    import resource
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "run")
        cmd = [sys.executable, "-m", "utrf", "hil", "grasp-hold", "--emulated",
               "--duration-s", f"{seconds:g}", "--out", out, "--quiet"]  # fmt: skip
        if obj is not None:
            cmd += ["--object", obj]
        if elf is not None:
            cmd += ["--elf", str(elf)]
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return {"seconds": seconds, "wall": wall, "cpu": cpu, "ok": done.returncode == 0, "obj": obj,
            "load": max(load0, os.getloadavg()[0]),
            "error": done.stderr.strip().splitlines()[-1:] if done.returncode else []}  # fmt: skip


def tick_load(elf: Path, fingers: int, telemetry_hz: int, seconds: float = 0.2) -> dict:
    """The tick's cycles with ``fingers`` under position control, over ``seconds`` or up to the
    tick in which the firmware latched a fault (OVERRUN, after which its fingers coast).

    The profile runs from before set_mode, so the worst figures hold the first controlled
    tick even when it overruns at once; the means count the ticks after set_mode's ack."""
    with EmulatedBoard(elf, realtime=False) as board:
        faults_seen = [m.FaultBits(0)]

        def on_fault(t) -> None:
            if isinstance(t.message, m.Fault):
                faults_seen[0] |= t.message.new_faults

        link = SimLink(board, on_telemetry=on_fault)
        link.handshake()
        link.request(m.SetTelemetry(rate_hz=telemetry_hz))
        link.request(m.ResetStats())
        board.profile_interrupt("TIMER2_COMPA")
        start_position_control(link.request, board.sim_time, fingers)
        faults_seen[0] = m.FaultBits(0)
        before = board.profile()["interrupt"]
        t0 = board.sim_time
        next_targets = t0
        while board.sim_time - t0 < seconds and not faults_seen[0]:
            if board.sim_time >= next_targets:
                targets = targets_at(board.sim_time)
                link.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=targets))
                next_targets += 0.05
            link.sleep(1e-3)
        faults = faults_seen[0]
        tick = board.profile()["interrupt"]
        n = tick.calls - before.calls

        def mean_since(attr: str) -> float:
            total = getattr(tick, attr) * tick.calls - getattr(before, attr) * before.calls
            return total / n if n > 0 else math.nan

        fw = link.request(m.GetStats())
        modes = link.request(m.GetStatus()).mode[:fingers]
        return {
            "fingers": fingers,
            "telemetry_hz": telemetry_hz,
            "tick": tick,
            "calls": n,
            "mean": mean_since("mean"),
            "mean_incl": mean_since("mean_incl"),
            "fw": fw,
            "faults": faults,
            "controlled": all(x == m.ControlMode.POSITION for x in modes) and not faults,
        }


def realtime(elf: Path, seconds: float) -> dict:
    """The board paced to the wall clock, a Link client over TCP, telemetry at 500 Hz."""
    with EmulatedBoard(elf, pty=False) as board:
        received = []
        with Link.open(board.url) as link:
            link.handshake()
            start_position_control(link.request, 0.0)
            link.request(m.SetTelemetry(rate_hz=500))
            time.sleep(0.2)
            while not link.telemetry.empty():
                link.telemetry.get_nowait()
            sim0, wall0, busy0 = board.sim_time, time.perf_counter(), board.busy_seconds
            end = wall0 + seconds
            while time.perf_counter() < end:
                link.request(
                    m.SetTargets(
                        kind=m.TargetKind.JOINT2_ANGLE,
                        mask=ALL,
                        value=targets_at(time.perf_counter()),
                    )
                )
                deadline = time.perf_counter() + 0.05
                while (left := deadline - time.perf_counter()) > 0:
                    try:
                        received.append(link.telemetry.get(timeout=left))
                    except Exception:  # queue.Empty
                        break
            wall = time.perf_counter() - wall0
            sim = board.sim_time - sim0
            busy = board.busy_seconds - busy0
            lost = link.stats().stream_lost
        return {
            "rtf": sim / wall,
            "capacity": sim / busy,
            "lag_events": board.lag_events,
            "telemetry_rate": sum(isinstance(t.message, m.State) for t in received) / wall,
            "stream_lost": lost,
        }


def pct(c: float) -> str:
    return f"{100 * c / PERIOD_CYCLES:.0f} %"


def driven_rows(runs: list[dict], seconds: float) -> list[str]:
    best = max(runs, key=lambda r: r["rtf"])
    rtfs = [r["rtf"] for r in runs]
    cpu_rtfs = ", ".join(f"{r['cpu_rtf']:.2f}" for r in runs)
    return [
        "| driven (`realtime=False`, as fast as it goes), MuJoCo plant (1 ms exchange), "
        f"five fingers commanded, {seconds:g} s simulated, best of {len(runs)} | "
        f"**{best['rtf']:.2f}x** real time (runs: {', '.join(f'{x:.2f}' for x in rtfs)}); "
        f"{best['cycles_per_s'] / 1e6:.1f} M simulated cycles per wall second; "
        f"**{best['cpu_rtf']:.2f}x** per second of the process's CPU time "
        f"(runs: {cpu_rtfs}); load average "
        f"{best['load']:.1f} |",
        f"| ... wall time in C (simavr and the plant, `run_plant`) / in Python (the client, "
        f"telemetry) | {100 * best['c_share']:.0f} % / {100 * (1 - best['c_share']):.0f} % "
        f"({best['c_per_sim'] * 1e3:.0f} ms in C per simulated second) |",
        f"| ... CPU cycles the firmware was awake (not in SLEEP; simavr skips slept cycles) | "
        f"{100 * best['awake']:.0f} % |",
        f"| ... state frames received / dropped by the firmware (`tx_dropped`) | "
        f"{best['telemetry_rate']:.0f} /s / {best['fw'].tx_dropped} |",
        f"| ... fingers that latched a fault (and coasted) | "
        f"{', '.join(str(f) for f, b in enumerate(best['faults']) if b) or 'none'} |",
    ]


def report(
    runs: list[dict],
    grasp: list[dict],
    ticks: list[dict],
    rt: dict,
    apart: dict,
    seconds: float,
) -> str:
    five = next(r for r in ticks if r["fingers"] == 5 and r["telemetry_hz"] == 500)
    lines = [
        BEGIN,
        "## Emulator",
        "",
        f"Measured with `make bench-emulator` (`python -m tools.bench_emulator`) on {cpu_name()}, "
        f"Python {platform.python_version()}, simavr 1.6 (Debian), {date.today().isoformat()}, "
        "with the real firmware (`build/firmware/utrf.elf`): fingers under position control "
        "track targets sweeping 0.3–1.3 rad at 0.5 Hz, heartbeats every 100 ms, the state "
        "stream at 500 Hz.",
        "",
        "### Real-time factor",
        "",
        "| what | result |",
        "|---|---|",
        *driven_rows(runs, seconds),
        *[
            f"| `utrf hil grasp-hold --emulated --duration-s {g['seconds']:g}"
            + (f" --object {g['obj']}`" if g["obj"] else "`")
            + " (the MuJoCo hand"
            + f"; a fresh process: start-up and picture included) | **{g['wall']:.1f} s** wall "
            f"({g['seconds'] / g['wall']:.1f}x real time) at load average {g['load']:.1f}; "
            f"**{g['cpu']:.1f} s** of CPU time ({g['seconds'] / g['cpu']:.1f}x"
            + ("" if g["ok"] else f"; FAILED: {' '.join(g['error'])}")
            + ") |"
            for g in grasp
        ],
        f"| served (`realtime=True`), a `Link` client on TCP, 500 Hz telemetry, {seconds:g} s | "
        f"{rt['rtf']:.3f}x (paced to the wall clock) |",
        f"| ... how fast it could have run meanwhile (simulated s per busy s) | "
        f"{rt['capacity']:.2f}x |",
        f"| ... times it fell > 100 ms behind the wall clock | {rt['lag_events']} |",
        f"| ... state frames received / lost in the stream | "
        f"{rt['telemetry_rate']:.0f} /s / {rt['stream_lost']} |",
        f"| served from a process of its own (`BoardProcess`), same client: real-time factor / "
        f"how fast it could have run | {apart['rtf']:.3f}x / {apart['capacity']:.2f}x "
        f"(stream frames lost: {apart['stream_lost']}) |",
        "",
        "### Control tick CPU load (timer-2 compare ISR, 1 kHz = 16,000 cycles)",
        "",
        "Cycles from the interrupt's entry to its RETI; *exclusive* leaves out the UART and ADC "
        "interrupts that nest in it (the firmware re-enables interrupts during its tick), "
        "*inclusive* counts them. *Start latency*: cycles from the compare match to the "
        "handler's entry (long while `loop()` masks the tick). The firmware latches OVERRUN "
        "when latency plus tick pass 16,000 cycles. Each row runs 0.2 s simulated from "
        "`set_mode`, or stops at the tick in which the firmware latched a fault.",
        "",
        "| fingers in POSITION | telemetry | ticks | mean excl. | worst excl. | mean incl. | "
        "worst incl. | worst start latency | firmware's tick_worst | faults latched |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in ticks:
        tk, f = r["tick"], r["fw"]
        faults = (r["faults"].name or str(int(r["faults"]))) if r["faults"] else "none"
        # a mean over ticks that mostly coasted after a fault would say nothing
        meaningful = r["controlled"] or r["calls"] >= 20
        mean = f"{r['mean']:,.0f} ({pct(r['mean'])})" if meaningful else "–"
        mean_incl = f"{r['mean_incl']:,.0f} ({pct(r['mean_incl'])})" if meaningful else "–"
        lines.append(
            f"| {r['fingers']} | {r['telemetry_hz']} Hz | {r['calls']} | "
            f"{mean} | {tk.worst:,} ({pct(tk.worst)}) | {mean_incl} | "
            f"{tk.worst_incl:,} ({pct(tk.worst_incl)}) | {tk.worst_latency:,} | "
            f"{f.tick_worst * 1e6:.0f} µs | {faults} |"
        )
    tk = five["tick"]
    lines += [
        "",
        (
            f"Five fingers with telemetry on: mean **{five['mean']:,.0f}** cycles "
            f"({pct(five['mean'])} of the tick), worst **{tk.worst:,}** ({pct(tk.worst)}) "
            f"exclusive of nested interrupts; worst inclusive {tk.worst_incl:,} "
            f"({pct(tk.worst_incl)})."
            if five["controlled"]
            else f"Five fingers with telemetry on: the first controlled tick took **{tk.worst:,}** "
            f"cycles ({pct(tk.worst)}) exclusive, {tk.worst_incl:,} ({pct(tk.worst_incl)}) with "
            f"the nested interrupts, after starting up to {tk.worst_latency:,} cycles late, and "
            f"the firmware latched {five['faults'].name} within {five['calls']} ticks and "
            "stopped the fingers: this build cannot run five fingers under position control at "
            "1 kHz (the rows above give the cycles each finger adds and how late the tick starts)."
        ),
        "",
        f"The machine is shared (2 cores; load average {os.getloadavg()[0]:.1f} when this "
        "section was written, each row gives its own; `uptime`'s 1-minute figure): wall-clock "
        "figures move with the load, CPU-time figures much less, so both are given; "
        "simulated cycles per wall second and the awake share say where the time goes. "
        "Driven, the plant steps in C inside the harness, and the harness runs from one frame the"
        " board sends to the next (`run_until_output`): Python looks at the output when a frame "
        "has come (135 times a simulated second with 100 Hz telemetry and heartbeats), not every "
        "millisecond (1000), nor every exchange while it waits for a reply. Inside simavr, the "
        "harness lets `avr_run_one` run on to the next cycle-timer event rather than return after"
        " every instruction (simavr 1.6 sets `run_cycle_limit` to 1; measured on the busy-loop "
        "firmware: 0.144 -> 0.090 s of CPU per simulated second, the same cycles and bytes), and "
        "leaves out the four PWM timers' events, timer 1's included, keeping its TCNT1 exact "
        "(0.046 -> 0.038 s on the idle-sleeping firmware of branch `line`). While the firmware "
        "sleeps (SLEEP, idle mode), simavr skips to its next event in one step (the harness "
        "stops the skip at a run's end, which simavr would pass): what remains is "
        "simavr interpreting the awake cycles. Profiled (py-spy) on the 120 s hold with the idle-"
        "sleeping firmware: 59 % of the time in C, then the run's per-sample work and its tracker"
        " (10 %), the Hand's telemetry (decoding, state and CSV log, 13 %), the figure (8 %), "
        "start-up imports (8 %), `SimLink` itself (3 %). "
        "The driven factor is how much faster than real time tests and scripts run the board; "
        "served, the board keeps to the wall clock and the capacity is its headroom, which a "
        "client in the same Python process shares (its threads and the board's take turns "
        "with the interpreter). The machine's other work shows in the spread of the runs. "
        "Without "
        "the harness's fix for simavr 1.6's level-triggered INT4/INT5 polling (D2 and D3 are "
        "PWM pins) the board ran at about 0.6x real time.",
        END,
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--elf", type=Path, default=DEFAULT_ELF)
    p.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per run")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--no-update", action="store_true", help="print only")
    p.add_argument(
        "--grasp-seconds", type=float, default=120.0, help="the grasp hold's length (0: skip)"
    )
    args = p.parse_args(argv)
    runs = [driven(args.elf, args.seconds, 500) for _ in range(args.runs)]
    elf = None if args.elf == DEFAULT_ELF else args.elf
    grasp = (
        [
            grasp_hold_wall(args.grasp_seconds, elf=elf),
            grasp_hold_wall(args.grasp_seconds, "ball", elf=elf),
        ]
        if args.grasp_seconds > 0
        else []
    )
    ticks = [tick_load(args.elf, k, 500) for k in range(6)] + [tick_load(args.elf, 5, 0)]
    rt = realtime(args.elf, args.seconds)
    apart = served_apart(args.elf, args.seconds)
    section = report(runs, grasp, ticks, rt, apart, args.seconds)
    print(section)
    if not args.no_update:
        write_section(BENCH_DOC, section, BEGIN, END)
        print(f"\nwritten to {BENCH_DOC}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
