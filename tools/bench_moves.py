"""Moves on the board's clock: how closely the fingers follow them, and what the paths cost.

- Tracking over the whole demo: ``utrf demo``'s run (the real firmware on the emulated board
  over its socket, the default sequence and the pose library's durations, ``--speed max``):
  per finger the RMS and the worst of Joint 2 measured against the setpoint its controller
  uses (the state stream's ``target``, 100 Hz), over every sample in closed loop; and each
  pose's largest settled error. The goal (issue 11): RMS at most 1 deg, worst at most 3 deg,
  every pose settled within 2 deg.
- The tick with five paths running: the firmware's own tick timing (``stats``: mean over
  1024 ticks, worst, timed to the cycle by timer 2 and timer 1) on the driven emulated board
  (simulated time), five fingers holding still against five fingers on moves (from 50 ms
  after they began), the 500 Hz stream on.

Prints a Markdown section and writes it into docs/benchmarks.md between the moves markers.
Run with ``make bench-moves``.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

from tools.doc_sections import cpu_name, write_section
from utrf.emulator import DEFAULT_ELF, EmulatedBoard
from utrf.hand import Hand
from utrf.hand.demo import DEFAULT_SEQUENCE, run_demo
from utrf.protocol import messages as m

REPO = Path(__file__).resolve().parents[1]
BENCH_DOC = REPO / "docs" / "benchmarks.md"
BEGIN = "<!-- BEGIN moves (make bench-moves) -->"
END = "<!-- END moves -->"
GOAL_RMS_DEG, GOAL_WORST_DEG, GOAL_SETTLE_DEG = 1.0, 3.0, 2.0


def tick_load(elf: Path, seed: int, moving: bool) -> m.Stats:
    """The firmware's tick timing over 2 s of simulated time, five fingers in POSITION."""
    with EmulatedBoard(elf, realtime=False, seed=seed) as board, Hand.emulated(board) as hand:
        hand.set_telemetry(m.MAX_TELEMETRY_HZ)
        hand.move([0.2] * 5, 0.5)
        if moving:  # 1.0 rad each, 2 s: every finger on its path the whole window
            hand.move([1.2, 1.2, 1.2, 1.2, 1.2], 2.0, wait=False)
        hand.clock.sleep(0.05)
        hand.reset_stats()
        hand.clock.sleep(1.8)
        return hand.stats()


def report(demo, loads: dict[str, m.Stats], args: argparse.Namespace, took: float) -> str:
    lines = [
        BEGIN,
        "## Moves",
        "",
        f"`make bench-moves` (`tools/bench_moves.py`), {date.today().isoformat()}, "
        f"{cpu_name()}; the board's figures are simulated time or its own cycle counts, "
        f"the host's wall clock only paces the demo (under the load of other jobs: real-time "
        f"factor {demo.realtime_factor:.2f}). Took {took:.0f} s.",
        "",
        f"**Tracking over the whole demo** ({' → '.join(DEFAULT_SEQUENCE)}, the pose "
        "library's durations; the real firmware on the emulated board over its socket, "
        "`utrf demo --speed max`, which prints the same table): Joint 2 measured against the "
        "setpoint its controller uses, every closed-loop sample of the 100 Hz stream. Goal: "
        f"RMS ≤ {GOAL_RMS_DEG:g}°, worst ≤ {GOAL_WORST_DEG:g}° (before board-side moves: "
        "7° and 28°).",
        "",
        "| finger | RMS (°) | worst (°) | samples | within the goal |",
        "|---|---|---|---|---|",
    ]
    for name, t in demo.tracking.items():
        ok = t.within(math.radians(GOAL_RMS_DEG), math.radians(GOAL_WORST_DEG))
        lines.append(
            f"| {name} | {math.degrees(t.rms):.2f} | {math.degrees(t.worst):.2f} | "
            f"{t.samples} | {'yes' if ok else 'NO'} |"
        )
    lines += [
        "",
        f"Each pose's largest error once settled (goal ≤ {GOAL_SETTLE_DEG:g}°; the mean of "
        "the last 0.2 s of its hold):",
        "",
        "| pose | settled | largest error (°) | paths stretched |",
        "|---|---|---|---|",
    ]
    for step in demo.steps:
        stretched = ", ".join(demo.stretched.get(step.name, ())) or "none"
        lines.append(
            f"| {step.index}. {step.name} | {'yes' if step.settled else 'NO'} | "
            f"{math.degrees(step.worst_error):.2f} | {stretched} |"
        )
    hold, move = loads["holding"], loads["moving"]
    lines += [
        "",
        "**The tick with five paths running** (the firmware's own timing, `stats`: mean over "
        "the last 1024 ticks, worst since `reset_stats`; driven emulated board, 500 Hz "
        "stream; 1.8 s of simulated time from 50 ms after the moves began):",
        "",
        "| five fingers | tick mean (µs) | tick worst (µs) | worst, % of the 1 ms period |",
        "|---|---|---|---|",
    ]
    for label, st in (("holding (no path)", hold), ("each on a move", move)):
        lines.append(
            f"| {label} | {st.tick_mean * 1e6:.0f} | {st.tick_worst * 1e6:.0f} | "
            f"{st.tick_worst * 1e5:.1f} % |"
        )
    lines += [
        "",
        "A moving finger's tick steps its setpoint (a 32-bit add), adds the feedforward to "
        "the PID's sum and every 5 ticks takes the next segment (one multiply); `loop()` "
        "works out the segments' end points, one ahead (`firmware/src/core/path.h`).",
        END,
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--elf", type=Path, default=DEFAULT_ELF)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-update", action="store_true", help="print only")
    args = p.parse_args(argv)
    if not args.elf.exists():
        print(f"bench_moves: {args.elf} not found: run `make firmware`", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        demo = run_demo(out, elf=args.elf, speed=None, seed=args.seed)
    loads = {
        "holding": tick_load(args.elf, args.seed, moving=False),
        "moving": tick_load(args.elf, args.seed, moving=True),
    }
    section = report(demo, loads, args, time.perf_counter() - t0)
    print(section)
    if not args.no_update:
        write_section(BENCH_DOC, section, BEGIN, END)
    return 0 if demo.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
