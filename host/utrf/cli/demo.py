"""``utrf demo``: the hand through open → rock-and-roll → shaka → fist → open, on the real
firmware (``build/firmware/utrf.elf``, ``make firmware``) running on the emulated board.

Starts the emulated board (simavr, paced to the wall clock so you can watch; the plant is the
MuJoCo hand), connects a Hand to it over its socket as to a real MEGA, moves through the poses
(one move each: the board runs the minimum-jerk paths, the pose's duration; then settling) with
a live table on a terminal (a line per pose elsewhere), and writes to ``--out`` (default
``out/demo``): a picture of each pose (the MuJoCo hand rendered at the measured angles, and each
finger drawn from the kinematics model with its target), ``trajectories.png`` (the joint angles
against their targets) and ``telemetry.csv`` (every sample, SI). Then prints where they are, and
each finger's tracking over the whole run (Joint 2 against the setpoint its controller used: RMS
and worst). ``make demo`` runs this. Exit codes: 0 every pose settled; 1 one did not; 2 bad input
(unknown pose, no firmware ELF).
"""

from __future__ import annotations

import argparse
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console, RenderableType
from rich.live import Live

from utrf.cli._hand_common import (
    EXIT_BAD_INPUT,
    EXIT_NOT_DONE,
    EXIT_OK,
    add_poses,
    error,
    guarded,
    load_poses,
)
from utrf.cli.emulate import speed_arg
from utrf.hand import Hand
from utrf.hand.demo import DEFAULT_SEQUENCE, Step, run_demo
from utrf.hand.tracking import format_tracking
from utrf.hand.view import state_table

DEFAULT_OUT = Path("out/demo")


@dataclass
class _Shown:
    """What the live view shows, set from the demo's callbacks."""

    hand: Hand | None = None
    step: Step | None = None


def _step_line(step: Step, total: int) -> str:
    if math.isnan(step.end):
        return f"[{step.index}/{total}] {step.name} ..."
    took = step.settled_at - step.start
    if step.settled:
        return (
            f"[{step.index}/{total}] {step.name}: settled in {took:.2f} s (board time), "
            f"largest error {math.degrees(step.worst_error):.1f} deg"
        )
    return f"[{step.index}/{total}] {step.name}: NOT settled: {step.reason}"


@guarded("demo")
def run(args: argparse.Namespace) -> int:
    from utrf.emulator import EmulatorError

    sequence = [s.strip() for s in args.sequence.split(",") if s.strip()]
    library = load_poses(args)
    console = Console()
    live_view = console.is_terminal and not args.no_live
    state = _Shown()
    lock = threading.Lock()
    live: Live | None = None

    def render() -> RenderableType:
        with lock:
            hand, step = state.hand, state.step
        if hand is None:
            return "starting the emulated board..."
        title = "UTRF-RoboHand demo"
        if step is not None:
            title += f": pose {step.index}/{len(sequence)}, {step.name}"
        footer = f"the real firmware on the emulated board at {hand.url}"
        return state_table(hand.latest, title=title, footer=footer)

    def on_connect(hand: Hand, _board: object) -> None:
        with lock:
            state.hand = hand
        print(f"emulated board up, the Hand connected to it at {hand.url}", flush=True)

    def on_step(step: Step) -> None:
        with lock:
            state.step = step
        line = _step_line(step, len(sequence))
        if live is not None:
            if not math.isnan(step.end):
                live.console.print(line)
        else:
            print(line, flush=True)

    print(
        f"utrf demo: {' -> '.join(sequence)} on the real firmware "
        f"({args.elf or 'the default firmware ELF'}) on the emulated board",
        flush=True,
    )
    t0 = time.monotonic()
    try:
        if live_view:
            live = Live(get_renderable=render, console=console, refresh_per_second=10)
            live.start()
        try:
            result = run_demo(
                args.out,
                sequence,
                elf=args.elf,
                speed=args.speed,
                move_s=args.duration,
                hold_s=args.hold,
                seed=args.seed,
                poses=library,
                on_connect=on_connect,
                on_step=on_step,
            )
        finally:
            if live is not None:
                live.stop()
    except EmulatorError as exc:
        error("demo", exc)
        return EXIT_BAD_INPUT
    took = time.monotonic() - t0
    print(
        f"done in {took:.1f} s (real-time factor {result.realtime_factor:.2f}); "
        f"{'every pose settled' if result.ok else 'NOT every pose settled'}. Files:"
    )
    for path in result.files:
        print(f"  {path}")
    print(format_tracking(result.tracking))
    for name, fingers in result.stretched.items():
        print(f"  {name}: the board stretched the paths of {', '.join(fingers)}")
    return EXIT_OK if result.ok else EXIT_NOT_DONE


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="the pose demo on the emulated board (pictures and plots in out/demo)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (out/demo)")
    p.add_argument(
        "--sequence",
        default=",".join(DEFAULT_SEQUENCE),
        metavar="P1,P2,...",
        help=f"poses in order (default {','.join(DEFAULT_SEQUENCE)})",
    )
    add_poses(p)
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="move time per pose (default: the pose's own, 1 s when it names none)",
    )
    p.add_argument("--hold", type=float, default=0.5, metavar="S", help="pause at each pose")
    p.add_argument(
        "--speed",
        type=speed_arg,
        default=1.0,
        metavar="X|max",
        help="the board's pace: X times real time (1), or 'max' (as fast as it goes)",
    )
    p.add_argument(
        "--elf",
        type=Path,
        help="firmware ELF (default: build/firmware/utrf.elf in a checkout, else built from "
        "the package's firmware sources into the user's cache)",
    )
    p.add_argument("--seed", type=int, default=0, help="the plant's noise seed")
    p.add_argument("--no-live", action="store_true", help="no live table, a line per pose")
    p.set_defaults(handler=run)
