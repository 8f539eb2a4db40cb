"""``utrf jog FINGER --to DEG | --by DEG --port URL``: move one finger, in degrees.

``--to`` moves the finger's Joint-2 angle to an angle, ``--by`` by a step from where it is
now (its setpoint when it is under closed-loop control, else its measured angle); along a
minimum-jerk path of ``--duration`` seconds (0: as fast as its motion limits allow), then
waits until it is within ``--tolerance`` degrees. The target is checked against the finger's
Joint-2 limits first (the refusal names them; nothing moves). The other fingers keep what they
do. Afterwards the finger holds the angle (goodbye: no HOST_TIMEOUT), or ``--then brake|coast``.
Connects without resetting the board (``--reset`` to reset it). Ctrl-C holds the finger where
it is and exits 130.

Exit codes: 0 settled; 1 not settled or a latched fault; 2 bad input (a target beyond the
finger's limits); 3 no board; 4 the board is in use; 130 interrupted.
"""

from __future__ import annotations

import argparse
import math

from utrf.cli._hand_common import (
    EXIT_NOT_DONE,
    EXIT_OK,
    add_port,
    connect_running,
    error,
    finger_arg,
    guarded,
    interrupted,
)
from utrf.hand.errors import FingerFaultError, NotControlledError, NotSettledError
from utrf.hand.view import state_line


@guarded("jog")
def run(args: argparse.Namespace) -> int:
    if args.duration < 0:
        raise ValueError(f"--duration must be >= 0 s, got {args.duration}")
    if not args.tolerance > 0:
        raise ValueError(f"--tolerance must be > 0 degrees, got {args.tolerance}")
    on_close = args.then
    with connect_running(args, "jog", on_close=on_close) as hand:
        name = hand.fingers[args.finger]
        try:
            now = hand.state().fingers[args.finger]
            start = now.target if now.closed_loop else now.theta2
            goal = math.radians(args.to) if args.to is not None else start + math.radians(args.by)
            hand.move(
                {args.finger: goal},
                args.duration,
                tolerance=math.radians(args.tolerance),
                timeout=args.timeout,
            )
        except (NotSettledError, FingerFaultError, NotControlledError) as exc:
            print(state_line(hand.state()))
            error("jog", exc)
            return EXIT_NOT_DONE
        except KeyboardInterrupt:
            return interrupted(hand, "jog")
        final = hand.state().fingers[args.finger]
        print(state_line(hand.state()))
    print(
        f"{name}: {math.degrees(final.theta2):.1f} deg (target {math.degrees(goal):.1f} deg, "
        f"within {args.tolerance:g} deg; left in {on_close})"
    )
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "jog",
        help="move one finger to an angle or by a step (degrees)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("finger", type=finger_arg, metavar="FINGER", help="a name or 0..4")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--to", type=float, metavar="DEG", help="the Joint-2 angle to go to")
    where.add_argument("--by", type=float, metavar="DEG", help="a step (+ flexes)")
    p.add_argument("--duration", type=float, default=0.5, metavar="S", help="move time (0.5)")
    p.add_argument("--tolerance", type=float, default=2.0, metavar="DEG", help="settled (2)")
    p.add_argument("--timeout", type=float, default=None, metavar="S", help="settling (3 s)")
    p.add_argument("--then", choices=("hold", "brake", "coast"), default="hold")
    add_port(p, reset=False)
    p.set_defaults(handler=run)
