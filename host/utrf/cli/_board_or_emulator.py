"""``--port URL`` or, without it, an emulated board started for the command (``dashboard``,
``record``): the real firmware on simavr with the MuJoCo hand, paced to the wall clock."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from pathlib import Path

from utrf.hand import Hand
from utrf.hand.client import OnClose
from utrf.protocol import messages as m


def add_board_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--port",
        metavar="URL",
        help="the board: a serial port (/dev/ttyACM0) or a pyserial URL "
        "(socket://127.0.0.1:PORT from `utrf emulate`); default: an emulated board started "
        "for this command",
    )
    p.add_argument(
        "--baud", type=int, default=m.DEFAULT_BAUD, help=f"default {m.DEFAULT_BAUD} (8N1)"
    )
    p.add_argument(
        "--boot-wait",
        type=float,
        default=2.5,
        metavar="S",
        help="seconds to wait for the board's boot frame after opening the port (the MEGA's "
        "auto-reset); 0 skips",
    )
    p.add_argument("--elf", type=Path, help="the emulated board's firmware ELF (no --port)")


@contextlib.contextmanager
def open_hand(
    args: argparse.Namespace, *, telemetry_hz: int, on_close: OnClose = "brake"
) -> Iterator[Hand]:
    """The Hand on ``--port``, or on an emulated board that lives as long as it does."""
    if args.port:
        with Hand.connect(
            args.port,
            baudrate=args.baud,
            boot_wait_s=args.boot_wait,
            telemetry_hz=telemetry_hz,
            on_close=on_close,
        ) as hand:
            yield hand
        return
    from utrf.emulator import EmulatedBoard

    with (
        EmulatedBoard(args.elf, realtime=True, pty=False) as board,
        Hand.emulated(board, telemetry_hz=telemetry_hz, on_close=on_close) as hand,
    ):
        yield hand
