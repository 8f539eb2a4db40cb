"""``utrf gains|limits|motion|safety|hardware get|set``: the board's settings from the shell.

``get [FINGER ...]`` prints a group for the fingers named (default all), in the units people
read (degrees for angles: rad/s as deg/s, 1/rad as 1/deg; the unit is printed beside each
value); ``--json`` prints SI. ``set FINGER NAME=VALUE ...`` (``safety set NAME=VALUE ...``,
board-wide) changes the fields named, in those same units, and keeps the others. Every value
is checked against the protocol's range before connecting: a refusal names the field and its
range, and nothing is sent. A setting lasts until the board resets; ``utrf eeprom save``
keeps it. The commands connect without resetting the board (``--reset`` to reset it).

Exit codes: 0; 1 the board refused (a hardware setting on a finger that is not idle); 2 bad
input (nothing sent); 3 no board; 4 the board is in use.
"""

from __future__ import annotations

import argparse
import functools
import json

from utrf.cli._hand_common import (
    EXIT_OK,
    add_port,
    connect_running,
    finger_arg,
    guarded,
)
from utrf.cli._settings import (
    GROUPS,
    Group,
    Value,
    parse_assignment,
    person_unit,
    read,
    show,
    write,
)
from utrf.models.geometry import HandGeometry

FINGERS = tuple(f.name for f in HandGeometry.default().fingers)


def _si(value: Value) -> float | int | str:
    return value.name.lower() if hasattr(value, "name") else value


def _print_table(group: Group, values: dict[str, dict[str, Value]]) -> None:
    cols = list(values)
    names = {f.name: f"{f.name} [{person_unit(f)[0] or '1'}]" for f in group.fields}
    width = max(len(n) for n in names.values()) + 2
    print(f"{group.name}: {group.what} (angles in degrees)")
    print(" " * width + "".join(f"{c:>12}" for c in cols))
    for field in group.fields:
        row = "".join(f"{show(field, values[c][field.name], with_unit=False):>12}" for c in cols)
        print(f"{names[field.name]:<{width}}{row}")


def _run_get(group: Group, args: argparse.Namespace) -> int:
    fingers = sorted(set(args.fingers)) if group.per_finger and args.fingers else range(5)
    with connect_running(args, f"{group.name} get", on_close="hold") as hand:
        if group.per_finger:
            values = {FINGERS[f]: read(hand, group, f) for f in fingers}
        else:
            values = {"board": read(hand, group, None)}
    if args.json:
        print(json.dumps({k: {n: _si(v) for n, v in vs.items()} for k, vs in values.items()}))
    else:
        _print_table(group, values)
    return EXIT_OK


def _run_set(group: Group, args: argparse.Namespace) -> int:
    changes = dict(parse_assignment(group, a) for a in args.assignments)  # before connecting
    finger = args.finger if group.per_finger else None
    with connect_running(args, f"{group.name} set", on_close="hold") as hand:
        before = read(hand, group, finger)
        write(hand, group, finger, changes)
        after = read(hand, group, finger)
    where = FINGERS[finger] if finger is not None else "board"
    for field in group.fields:
        if field.name in changes:
            old, new = show(field, before[field.name]), show(field, after[field.name])
            print(f"{where} {group.name}.{field.name}: {old} -> {new}")
    print("(until the board resets: `utrf eeprom save` keeps it)")
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    for group in GROUPS.values():
        p = subparsers.add_parser(
            group.name,
            help=f"get or set {group.what} (degrees for angles)",
            description=__doc__,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
        fields = ", ".join(f.name for f in group.fields)
        get = sub.add_parser("get", help=f"print {group.what}")
        if group.per_finger:
            get.add_argument(
                "fingers", nargs="*", type=finger_arg, metavar="FINGER", help="default: all"
            )
        add_port(get, reset=False)
        get.add_argument("--json", action="store_true", help="SI values as JSON")
        get.set_defaults(handler=guarded(f"{group.name} get")(functools.partial(_run_get, group)))
        put = sub.add_parser("set", help=f"change {group.what}: NAME=VALUE ({fields})")
        if group.per_finger:
            put.add_argument("finger", type=finger_arg, metavar="FINGER")
        put.add_argument("assignments", nargs="+", metavar="NAME=VALUE", help=fields)
        add_port(put, reset=False)
        put.set_defaults(handler=guarded(f"{group.name} set")(functools.partial(_run_set, group)))
