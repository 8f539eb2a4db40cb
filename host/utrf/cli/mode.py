"""``utrf mode MODE [FINGER ...] --port URL``: set the fingers' control mode (default all).

``coast`` (motor outputs off: the fingers are free), ``brake`` (motor terminals shorted:
unpowered, damped), ``position`` (hold where they are now, in closed loop), ``grasp`` (close
toward the finger's target with at most ``--effort`` duty; holds on contact) and ``duty``
(open loop at the signed ``--duty``, positive flexes, supervised by the board's stall, limit
and encoder rules) for ``--for`` seconds, then brake: an open-loop motor never runs after the
command. Modes left after the command stay (goodbye: no HOST_TIMEOUT). A finger with a latched
fault cannot be driven (``utrf clear-faults``). Connects without resetting the board
(``--reset`` to reset it). Ctrl-C holds closed-loop fingers where they are, brakes the others.

Exit codes: 0; 1 a latched fault; 2 bad input; 3 no board; 4 the board is in use; 130
interrupted.
"""

from __future__ import annotations

import argparse

from utrf.cli._hand_common import (
    EXIT_OK,
    add_port,
    connect_running,
    finger_arg,
    guarded,
    interrupted,
)
from utrf.hand.view import state_line

MODES = ("coast", "brake", "position", "grasp", "duty")


@guarded("mode")
def run(args: argparse.Namespace) -> int:
    fingers = sorted(set(args.fingers)) if args.fingers else list(range(5))
    duty: float = 0.0 if args.duty is None else args.duty
    if args.mode == "duty":
        if args.duty is None or not -1.0 <= args.duty <= 1.0:
            raise ValueError(f"duty needs --duty in -1..1 (a fraction), got {args.duty}")
        if not 0 < args.seconds <= 10.0:
            raise ValueError(f"--for must lie in (0, 10] s, got {args.seconds}")
    elif args.duty is not None:
        raise ValueError("--duty is for the duty mode only")
    if not 0.0 <= args.effort <= 1.0:
        raise ValueError(f"--effort must lie in 0..1 (a fraction), got {args.effort}")
    with connect_running(args, "mode", on_close="hold") as hand:
        try:
            if args.mode == "position":
                hand.hold(fingers)
            elif args.mode == "duty":
                hand.set_mode("duty", fingers, duty=duty)
                hand.clock.sleep(args.seconds)
                hand.brake(fingers)
            else:
                hand.set_mode(args.mode, fingers, effort=args.effort)
        except KeyboardInterrupt:
            return interrupted(hand, "mode")
        print(state_line(hand.state()))
    names = ", ".join(hand.fingers[i] for i in fingers)
    left = "brake, after the duty" if args.mode == "duty" else args.mode
    print(f"{names}: {left}")
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "mode",
        help="set the fingers' control mode",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("mode", choices=MODES)
    p.add_argument("fingers", nargs="*", type=finger_arg, metavar="FINGER", help="default: all")
    p.add_argument("--duty", type=float, metavar="F", help="duty: signed fraction (+ flexes)")
    p.add_argument(
        "--for", dest="seconds", type=float, default=0.5, metavar="S", help="duty: time (0.5)"
    )
    p.add_argument("--effort", type=float, default=1.0, metavar="F", help="grasp: largest duty")
    add_port(p, reset=False)
    p.set_defaults(handler=run)
