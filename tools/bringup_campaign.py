"""Seeded builds of the twin brought up, their faults against the bring-up's findings
(``make bringup-campaign``; the table goes into docs/bringup.md).

    python -m tools.bringup_campaign --builds 50 --update docs/bringup.md

Each build is ``BuildFaults.random(seed, faults)`` (every motor within ±30 % of the model's,
``faults`` faults on distinct fingers); the whole hand is brought up on a driven board
(simulated time) with the confirmation answered yes. A fault counts as named when a finding of
its kind is on its finger; a finding on a finger whose build has no fault of that kind is a
false diagnosis. The board time of each bring-up is recorded (the goal: a whole hand in at
most 2 minutes of board time).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from tools.doc_sections import cpu_name, write_section
from utrf.bringup import bringup
from utrf.emulator import BuildFaults, EmulatedBoard
from utrf.hand import Hand

# the twin's fault kind -> the finding that names it
EXPECTED = {
    "swap-leads": "leads-swapped",
    "swap-lead-a": "lead-a-swapped",
    "invert-magnet": "encoder-inverted",
    "magnet-offset": "magnet-offset",
    "off-centre": "not-monotonic",
    "slack": "slack",
    "weak-motor": "friction",
    "slow-motor": "slow-motor",
    "narrow-range": "narrow-range",
    "friction": "friction",
    "unpowered": "no-motion",
    "unplugged": "encoder-signal",
    "swap-cables": "cable-swap",
    "swap-encoders": "cable-swap",
}
BEGIN, END = "<!-- BEGIN bringup-campaign -->", "<!-- END bringup-campaign -->"


def run_build(seed: int, faults: int) -> dict[str, Any]:
    build = BuildFaults.random(seed, faults)
    truth = {(EXPECTED[k], f) for k, fs in build.faults() for f in fs}
    t0 = time.monotonic()
    with (
        EmulatedBoard(realtime=False, seed=seed, build=build) as board,
        Hand.emulated(board) as hand,
    ):
        result = bringup(hand, confirm=lambda text: True)
    found = {(fd.kind, hand.finger_index(fd.finger)) for fd in result.findings}
    return {
        "seed": seed,
        "faults": [f"{k}:{','.join(map(str, fs))}" for k, fs in build.faults()],
        "missed": sorted(f"{k}@{f}" for k, f in truth - found),
        "false": sorted(f"{k}@{f}" for k, f in found - truth),
        "saved": result.saved,
        "board_time_s": result.board_time_s,
        "wall_s": time.monotonic() - t0,
    }


def table(rows: list[dict[str, Any]], command: str) -> str:
    lines = [
        BEGIN,
        f"Measured with `{command}` on {cpu_name()} (2 cores shared with other jobs); board "
        "time is simulated time.",
        "",
        "| seed | faults | missed | false | saved | board time (s) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['seed']} | {' '.join(r['faults']) or '-'} | {' '.join(r['missed']) or '-'} "
            f"| {' '.join(r['false']) or '-'} | {'yes' if r['saved'] else 'no'} "
            f"| {r['board_time_s']:.1f} |"
        )
    missed = sum(len(r["missed"]) for r in rows)
    false = sum(len(r["false"]) for r in rows)
    worst = max(float(r["board_time_s"]) for r in rows)
    lines += [
        "",
        f"{len(rows)} builds: {missed} faults missed, {false} false diagnoses; the longest "
        f"whole-hand bring-up took {worst:.1f} s of board time.",
        END,
    ]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--builds", type=int, default=50)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--faults", type=int, default=3)
    ap.add_argument("--update", type=Path, help="write the table into this Markdown file")
    ap.add_argument("--json", type=Path, help="every build's result")
    args = ap.parse_args()
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.builds):
        rows.append(run_build(seed, args.faults))
        print(json.dumps(rows[-1]), flush=True)
    command = f"python -m tools.bringup_campaign --builds {args.builds} --faults {args.faults}"
    text = table(rows, command)
    print(text)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if args.update:
        write_section(args.update, text, BEGIN, END)


if __name__ == "__main__":
    main()
