"""``utrf bringup --port URL``: a new hand's first power-on, guided (docs/bringup.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from utrf.cli._hand_common import EXIT_NOT_DONE, EXIT_OK, add_port, connect, guarded


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "bringup",
        help="bring up a new hand: find wiring and build mistakes, calibrate, tune, save",
        description="Finger by finger, with small bounded open-loop pulses (motors braked "
        "between steps): the encoder, the motors' wiring and direction, the joint's stops "
        "(the encoder's zero and the limits), the plant and the gains, checked closed loop. "
        "Asks before saving anything to the board's EEPROM; Ctrl-C leaves the motors off and "
        "the saved configuration as it was. Angles printed in degrees.",
    )
    add_port(p)
    p.add_argument(
        "--finger", action="append", default=None, metavar="NAME",
        help="only this finger (name or 0..4; repeat for more); default all",
    )  # fmt: skip
    p.add_argument(
        "--out", type=Path, default=Path("bringup-report"), metavar="DIR",
        help="the report folder (report.md, pictures, measurements.json); default ./bringup-report",
    )  # fmt: skip
    p.add_argument("--yes", action="store_true", help="save without asking (tests, scripts)")
    p.add_argument(
        "--resume", action="store_true",
        help="skip the fingers the report folder's progress.json already has",
    )  # fmt: skip
    p.add_argument(
        "--upto", choices=("wiring", "stops", "plant", "check"), default="check",
        help="the last step on each finger (default: all of them)",
    )  # fmt: skip
    p.add_argument(
        "--demo", action="store_true",
        help="then the demo's poses: does its tracking goal hold (RMS <= 1 deg, worst <= 3 deg)",
    )  # fmt: skip
    p.set_defaults(handler=run)


def _ask(text: str) -> bool:
    print(text)
    try:
        answer = input("Save this configuration to the board's EEPROM? [y/N] ")
    except EOFError:
        return False
    return answer.strip().lower() in ("y", "yes")


@guarded("bringup")
def run(args: argparse.Namespace) -> int:
    from utrf.bringup import bringup

    fingers = None
    if args.finger:
        fingers = [int(f) if f.isdigit() else f for f in args.finger]
    with connect(args, on_close="brake") as hand:
        hand.set_safety(heartbeat_timeout=max(0.5, hand.safety().heartbeat_timeout))
        result = bringup(
            hand,
            args.out,
            fingers=fingers,
            confirm=(lambda text: print(text) or True) if args.yes else _ask,
            on_step=lambda text: print(f"- {text}", flush=True),
            resume=args.resume,
            upto=args.upto,
        )
        goal = None
        if args.demo and result.ok and (result.saved or result.unchanged):
            from utrf.bringup.demo_goal import demo_goal

            print("- the demo's poses on the hand brought up", flush=True)
            goal = demo_goal(hand)
    for fd in result.findings:
        print(f"  {fd}")
    print(result.message)
    if goal is not None:
        print(goal.line())
    print(f"report: {args.out / 'report.md'}", file=sys.stderr)
    return EXIT_OK if result.ok and (goal is None or goal.ok) else EXIT_NOT_DONE
