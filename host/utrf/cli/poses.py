"""``utrf poses``: the pose library, as a table (Joint-2 targets in degrees) or JSON (SI).

The built-in poses (``utrf/data/poses.toml``), then the user's file (``~/.config/utrf/
poses.toml``, or ``$UTRF_POSES``), then each ``--poses FILE``; a later pose replaces an
earlier one of the same name. Exit codes: 0, or 2 for a pose file that cannot be used (the
message names the file, the pose and the field).
"""

from __future__ import annotations

import argparse
import json
import math

from rich.console import Console
from rich.table import Table

from utrf.cli._hand_common import EXIT_OK, add_poses, guarded, load_poses
from utrf.models.geometry import HandGeometry


@guarded("poses")
def run(args: argparse.Namespace) -> int:
    library = load_poses(args)
    hand = HandGeometry.default()
    names = [f.name for f in hand.fingers]
    if args.json:
        out = {}
        for name, pose in library.items():
            out[name] = {
                "description": pose.description,
                "source": pose.source,
                "theta2_rad": dict(zip(names, map(float, pose.theta2(hand)), strict=True)),
                "q_m": dict(zip(names, map(float, pose.q(hand)), strict=True)),
                "grasp": None
                if pose.grasp is None
                else {"effort": pose.grasp.effort, "load_kg": pose.grasp.load_kg},
            }
        print(json.dumps(out, indent=2))
        return EXIT_OK
    table = Table(
        title=f"{len(library)} poses",
        caption="Joint-2 targets in degrees; grasp: GRASP mode with this effort (duty)",
    )
    table.add_column("pose")
    for n in names:
        table.add_column(n, justify="right")
    table.add_column("grasp", justify="right")
    table.add_column("description")
    for name, pose in library.items():
        theta2 = pose.theta2(hand)
        table.add_row(
            name,
            *(f"{math.degrees(t):.0f}" for t in theta2),
            "" if pose.grasp is None else f"{pose.grasp.effort:.2f}",
            pose.description,
        )
    Console(width=max(Console().width, 120)).print(table)
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "poses",
        help="list the pose library (built-in and your own)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_poses(p)
    p.add_argument("--json", action="store_true", help="JSON (SI: rad, m) instead of a table")
    p.set_defaults(handler=run)
