"""``utrf zero``, ``utrf clear-faults``, ``utrf eeprom save|load``: the board's upkeep.

``zero FINGER ...`` takes the present encoder readings as Joint-2 angle 0 (the fingers must be
straight and idle: COAST or BRAKE, ``utrf mode brake FINGER``). ``clear-faults [FINGER ...]``
clears latched faults (default all fingers) and says which it cleared; a finger whose fault
stopped its motors stays in COAST (command it again), one held by the HOLD safe action keeps
holding. ``eeprom save`` writes the running configuration to the EEPROM (about 1 s; it is
what the board loads at power-on); ``eeprom load`` replaces it with the saved one, or with the
firmware's defaults (``--defaults``); every finger must be idle. The commands connect without
resetting the board (``--reset`` to reset it).

Exit codes: 0; 1 a finger was not idle, or the board refused; 2 bad input; 3 no board;
4 the board is in use.
"""

from __future__ import annotations

import argparse

from utrf.cli._hand_common import (
    EXIT_NOT_DONE,
    EXIT_OK,
    add_port,
    connect_running,
    error,
    finger_arg,
    guarded,
)
from utrf.hand import Hand, fault_names
from utrf.hand.view import state_line
from utrf.protocol import messages as m

IDLE = (m.ControlMode.COAST, m.ControlMode.BRAKE)


def _busy(hand: Hand, fingers: list[int], command: str, why: str) -> bool:
    """Say which fingers are not idle (nothing is sent then)."""
    st = hand.state()
    busy = [st.fingers[i] for i in fingers if st.fingers[i].mode not in IDLE]
    if busy:
        names = ", ".join(f"{f.name} is in {f.mode.name}" for f in busy)
        error(command, f"{names}: {why} (`utrf mode brake FINGER` first)")
    return bool(busy)


@guarded("zero")
def run_zero(args: argparse.Namespace) -> int:
    fingers = sorted(set(args.fingers))
    with connect_running(args, "zero", on_close="hold") as hand:
        if _busy(hand, fingers, "zero", "zeroing needs the finger straight and idle"):
            return EXIT_NOT_DONE
        hand.calibrate_zero(fingers)
        print(state_line(hand.state()))
    names = ", ".join(hand.fingers[i] for i in fingers)
    print(f"zeroed: {names} (the present angle is 0 deg; `utrf eeprom save` keeps it)")
    return EXIT_OK


@guarded("clear-faults")
def run_clear(args: argparse.Namespace) -> int:
    fingers = sorted(set(args.fingers)) if args.fingers else list(range(5))
    with connect_running(args, "clear-faults", on_close="hold") as hand:
        before = hand.state()
        hand.clear_faults(fingers)
        after = hand.state()
        print(state_line(after))
    cleared = [
        f"{f.name} ({fault_names(f.faults)})"
        for f in before.fingers
        if f.faults and f.index in fingers
    ]
    print("cleared: " + (", ".join(cleared) if cleared else "nothing was latched"))
    still = [f"{f.name} ({fault_names(f.faults)})" for f in after.fingers if f.faults]
    if still:
        error("clear-faults", "latched again (the cause persists): " + ", ".join(still))
        return EXIT_NOT_DONE
    return EXIT_OK


@guarded("eeprom")
def run_eeprom(args: argparse.Namespace) -> int:
    with connect_running(args, f"eeprom {args.action}", on_close="hold") as hand:
        if args.action == "save":
            hand.save_config()
            print("saved: the running configuration is in the EEPROM (loaded at power-on)")
            return EXIT_OK
        if _busy(hand, list(range(5)), "eeprom load", "loading needs every finger idle"):
            return EXIT_NOT_DONE
        source = "defaults" if args.defaults else "eeprom"
        hand.load_config(source)
    what = "the firmware's defaults" if args.defaults else "the configuration saved in the EEPROM"
    print(f"loaded: {what} is now in use")
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    def parser(name: str, help_: str) -> argparse.ArgumentParser:
        return subparsers.add_parser(
            name,
            help=help_,
            description=__doc__,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )

    p = parser("zero", "take the present angles as 0 (idle, straight)")
    p.add_argument("fingers", nargs="+", type=finger_arg, metavar="FINGER")
    add_port(p, reset=False)
    p.set_defaults(handler=run_zero)
    p = parser("clear-faults", "clear latched faults")
    p.add_argument("fingers", nargs="*", type=finger_arg, metavar="FINGER", help="default: all")
    add_port(p, reset=False)
    p.set_defaults(handler=run_clear)
    p = parser("eeprom", "save or load the configuration in EEPROM")
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    save = sub.add_parser("save", help="write the running configuration to the EEPROM")
    add_port(save, reset=False)
    save.set_defaults(handler=run_eeprom)
    load = sub.add_parser("load", help="use the saved configuration (every finger idle)")
    load.add_argument("--defaults", action="store_true", help="the firmware's defaults instead")
    add_port(load, reset=False)
    load.set_defaults(handler=run_eeprom)
