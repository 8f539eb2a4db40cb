"""``utrf pose NAME --port URL``: move the hand to a pose and wait until it is settled.

Connects (riding out the board's auto-reset), moves every finger along a minimum-jerk path
the board runs over ``--duration`` seconds (default: the pose's own), waits until each is
within ``--tolerance`` degrees of its target and prints the result. On a terminal a live
table follows the fingers meanwhile. Afterwards the hand is left as ``--then`` says:
``hold`` (the default: the board keeps the pose in closed loop), ``brake`` or ``coast``; the
command then says goodbye to the board, whose host-silence rule stands down, so a held pose
latches no HOST_TIMEOUT and the next command (``--no-reset``) takes over cleanly. A command
killed without its goodbye leaves HOST_TIMEOUT latched (the board's safe action applied).

Exit codes: 0 settled; 1 not settled (the reason names each finger and how far off it is)
or a latched fault; 2 bad input (unknown pose, bad pose file); 3 the board could not be
reached or spoke another protocol; 4 the board is in use; 130 interrupted (Ctrl-C: the
fingers are held where they are, in closed loop, and the command prints their state).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys

from rich.console import Console
from rich.live import Live
from rich.table import Table

from utrf.cli._hand_common import (
    EXIT_NOT_DONE,
    EXIT_OK,
    add_port,
    add_poses,
    connect,
    error,
    guarded,
    interrupted,
    load_poses,
)
from utrf.hand import HandState
from utrf.hand.errors import FingerFaultError, NotControlledError, NotSettledError
from utrf.hand.view import state_line, state_table


def _json_state(st: HandState) -> dict:
    return {
        f.name: {
            "theta2_rad": f.theta2,
            "target_rad": f.target,
            "mode": f.mode.name,
            "faults": int(f.faults),
        }
        for f in st
    }


@guarded("pose")
def run(args: argparse.Namespace) -> int:
    library = load_poses(args)
    pose = library[args.name]  # KeyError naming the poses: exit 2, before connecting
    tolerance = math.radians(args.tolerance)
    if not tolerance > 0:
        raise ValueError(f"--tolerance must be > 0 degrees, got {args.tolerance}")
    console = Console(stderr=False)
    live_view = console.is_terminal and not args.json
    with connect(args, poses=library, on_close=args.then, log_path=args.log) as hand:
        goal = pose.theta2(hand.geometry)
        title = f"{pose.name}: {pose.description}"
        outcome: BaseException | None = None

        def render() -> Table:
            return state_table(hand.latest, title=title, goal=goal, tolerance=tolerance)

        display: contextlib.AbstractContextManager[object]
        if live_view:
            display = Live(get_renderable=render, console=console, refresh_per_second=10)
        else:
            display = contextlib.nullcontext()
            if not args.json:
                took = args.duration if args.duration is not None else pose.duration_s or 1.0
                print(f"moving to {pose.name} over {took:g} s ...", flush=True)
        stopped = False
        with display:
            try:
                hand.pose(pose, args.duration, tolerance=tolerance, timeout=args.timeout)
            except (NotSettledError, FingerFaultError, NotControlledError) as exc:
                outcome = exc
            except KeyboardInterrupt:
                stopped = True
        if stopped:  # after the live table is gone
            return interrupted(hand, "pose")
        final = hand.state()
        if args.json:
            print(
                json.dumps(
                    {
                        "pose": pose.name,
                        "settled": outcome is None,
                        "reason": None if outcome is None else str(outcome),
                        "tolerance_rad": tolerance,
                        "fingers": _json_state(final),
                    }
                )
            )
        elif not live_view:
            print(state_line(final))
        if outcome is not None:
            error("pose", outcome)
            return EXIT_NOT_DONE
        if not args.json:
            print(
                f"settled: {pose.name}, every finger within {args.tolerance:g} deg of its "
                f"target (left in {args.then})",
                file=sys.stdout,
            )
        return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "pose",
        help="move the hand to a pose and wait until it is settled",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", help="a pose of the library (`utrf poses` lists them)")
    add_port(p)
    add_poses(p)
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="move time (default: the pose's own, 1 s when it names none)",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=2.0,
        metavar="DEG",
        help="settled within this many degrees of the Joint-2 target (2)",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=None,
        metavar="S",
        help="settling time allowed after the move's paths end (3 s)",
    )
    p.add_argument(
        "--then",
        choices=("hold", "brake", "coast"),
        default="hold",
        help="what the hand does after the command (default hold: see above)",
    )
    p.add_argument("--log", metavar="FILE", help="append the telemetry to this CSV (SI)")
    p.add_argument("--json", action="store_true", help="print the outcome as JSON (SI)")
    p.set_defaults(handler=run)
