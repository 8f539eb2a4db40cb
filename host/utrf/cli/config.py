"""``utrf config backup FILE`` / ``utrf config restore FILE``: the board's whole running
configuration as a TOML file people can read and diff.

The file holds every setting of every group (``[safety]``, ``[finger.NAME.gains]``,
``.limits``, ``.motion``, ``.hardware``) in SI units (rad, s, Hz, duty fractions), as the API
has them; a restore of a backup sets exactly what was read (a backup after it is the same
file). ``restore`` checks the whole file against the protocol's ranges before connecting (a
refusal names the file, the setting and its range; nothing is sent), then prints what it
changes, in degrees for angles, and sets it (``--dry-run``: only prints). A file may name only
some settings: the others keep their values. Hardware settings change only on idle fingers.
A restore lasts until the board resets: ``utrf eeprom save`` keeps it. Connects without
resetting the board (``--reset`` to reset it).

Exit codes: 0; 1 a finger was not idle for a hardware change, or the board refused; 2 bad
input (an unreadable file, an unknown or out-of-range setting); 3 no board; 4 the board is
in use.
"""

from __future__ import annotations

import argparse
import tomllib
from enum import IntEnum
from pathlib import Path

from utrf import __version__
from utrf.cli._hand_common import EXIT_NOT_DONE, EXIT_OK, add_port, connect_running, error, guarded
from utrf.cli._settings import GROUPS, Group, SettingError, Value, check, read, show, write
from utrf.hand import Hand
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as m
from utrf.protocol.codec import Field, to_f32

FINGERS = tuple(f.name for f in HandGeometry.default().fingers)
FINGER_GROUPS = tuple(g for g in GROUPS.values() if g.per_finger)
SAFETY = GROUPS["safety"]

#: where a setting lives: (finger index or None, group)
Key = tuple[int | None, Group]
Config = dict[Key, dict[str, Value]]


def _toml_value(field: Field, value: Value) -> str:
    if isinstance(value, IntEnum):
        return f'"{value.name.lower()}"'
    if isinstance(value, int):
        return str(value)
    if field.type == "f32":  # the shortest text that is the same binary32 on the wire
        for digits in range(1, 10):
            text = f"{value:.{digits}g}"
            if to_f32(float(text)) == value:
                return repr(float(text))
    return repr(float(value))  # the shortest text that reads back as the same float


def to_toml(config: Config, identity: m.Identity) -> str:
    lines = [
        f"# UTRF-RoboHand board configuration, written by `utrf config backup` (utrf "
        f"{__version__}).",
        "# SI units: rad, rad/s, s, Hz; duties as fractions. `utrf config restore FILE` shows",
        "# what it changes and sets it; `utrf eeprom save` then keeps it on the board.",
        f"# firmware {identity.fw_major}.{identity.fw_minor}.{identity.fw_patch}, protocol "
        f"{identity.protocol_version}, schema 0x{identity.schema_hash:08x}",
    ]
    for (finger, group), values in config.items():
        table = group.name if finger is None else f"finger.{FINGERS[finger]}.{group.name}"
        lines += ["", f"[{table}]"]
        for field in group.fields:
            unit = f"  # {field.unit}" if field.unit and field.unit != "1" else ""
            lines.append(f"{field.name} = {_toml_value(field, values[field.name])}{unit}")
    return "\n".join(lines) + "\n"


def from_toml(path: Path) -> Config:
    """The settings a file names, each checked; SettingError naming the file otherwise."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SettingError(f"{path}: cannot read it as TOML: {exc}") from exc
    out: Config = {}

    def take(finger: int | None, group: Group, table: object, where: str) -> None:
        if not isinstance(table, dict):
            raise SettingError(f"{path}: [{where}] must be a table")
        values: dict[str, Value] = {}
        for name, value in table.items():
            try:
                values[name] = check(group, group.field(name), value)
            except SettingError as exc:
                raise SettingError(f"{path}: [{where}]: {exc}") from None
        out[(finger, group)] = values

    for top, table in data.items():
        if top == "safety":
            take(None, SAFETY, table, "safety")
        elif top == "finger" and isinstance(table, dict):
            for name, groups in table.items():
                if name not in FINGERS:
                    raise SettingError(f"{path}: no finger {name!r}; fingers are {list(FINGERS)}")
                if not isinstance(groups, dict):
                    raise SettingError(f"{path}: [finger.{name}] must be a table")
                for gname, gtable in groups.items():
                    group = GROUPS.get(gname)
                    if group is None or not group.per_finger:
                        names = [g.name for g in FINGER_GROUPS]
                        raise SettingError(
                            f"{path}: [finger.{name}.{gname}]: no such group; groups are {names}"
                        )
                    take(FINGERS.index(name), group, gtable, f"finger.{name}.{gname}")
        else:
            raise SettingError(f"{path}: unknown table [{top}]; tables are [safety], [finger.*]")
    return out


def _wire(group: Group, name: str, value: Value) -> object:
    """What the board holds: values alike on the wire are the same setting."""
    return group.field(name).to_raw(value, name)


def read_all(hand: Hand) -> Config:
    config: Config = {(None, SAFETY): read(hand, SAFETY, None)}
    for i in range(len(FINGERS)):
        for group in FINGER_GROUPS:
            config[(i, group)] = read(hand, group, i)
    return config


@guarded("config backup")
def run_backup(args: argparse.Namespace) -> int:
    with connect_running(args, "config backup", on_close="hold") as hand:
        text = to_toml(read_all(hand), hand.identity)
    args.file.write_text(text)
    print(f"wrote {args.file}: every setting of the board (SI units)")
    return EXIT_OK


@guarded("config restore")
def run_restore(args: argparse.Namespace) -> int:
    wanted = from_toml(args.file)  # checked before connecting
    with connect_running(args, "config restore", on_close="hold") as hand:
        changes: Config = {}
        for (finger, group), values in wanted.items():
            now = read(hand, group, finger)
            diff = {
                k: v for k, v in values.items() if _wire(group, k, now[k]) != _wire(group, k, v)
            }
            where = "board" if finger is None else FINGERS[finger]
            for name, new in diff.items():
                field = group.field(name)
                print(
                    f"{where} {group.name}.{name}: {show(field, now[name])} -> {show(field, new)}"
                )
            if diff:
                changes[(finger, group)] = diff
        if not changes:
            print(f"{args.file}: the board already has every setting it names")
            return EXIT_OK
        if args.dry_run:
            print(f"(dry run: nothing was set; {sum(len(v) for v in changes.values())} changes)")
            return EXIT_OK
        st = hand.state()
        busy = sorted(
            {
                f"{FINGERS[f]} is in {st.fingers[f].mode.name}"
                for f, g in changes
                if g.name == "hardware"
                and f is not None
                and st.fingers[f].mode not in (m.ControlMode.COAST, m.ControlMode.BRAKE)
            }
        )
        if busy:
            error(
                "config restore",
                f"{', '.join(busy)}: hardware settings change only on idle fingers "
                "(`utrf mode brake`); nothing was set",
            )
            return EXIT_NOT_DONE
        for (finger, group), diff in changes.items():
            write(hand, group, finger, diff)
    print(f"restored {args.file}: {sum(len(v) for v in changes.values())} settings changed")
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "config",
        help="back the board's configuration up to a TOML file, or restore it",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    b = sub.add_parser("backup", help="write every setting to FILE (TOML, SI)")
    b.add_argument("file", type=Path, metavar="FILE")
    add_port(b, reset=False)
    b.set_defaults(handler=run_backup)
    r = sub.add_parser("restore", help="show what FILE changes, then set it")
    r.add_argument("file", type=Path, metavar="FILE")
    r.add_argument("--dry-run", action="store_true", help="only show what would change")
    add_port(r, reset=False)
    r.set_defaults(handler=run_restore)
