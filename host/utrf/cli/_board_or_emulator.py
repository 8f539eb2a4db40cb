"""``--port URL`` or, without it, an emulated board started for the command (``dashboard``,
``record``): the real firmware on simavr with the MuJoCo hand, paced to the wall clock."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from pathlib import Path

from utrf.cli._hand_common import add_port, connect
from utrf.hand import Hand
from utrf.hand.client import OnClose


def add_board_options(p: argparse.ArgumentParser, *, reset: bool = True) -> None:
    """``_hand_common.add_port`` with --port optional, and --elf for the emulated board."""
    add_port(p, reset=reset, emulated=True)
    p.add_argument("--elf", type=Path, help="the emulated board's firmware ELF (no --port)")


@contextlib.contextmanager
def open_hand(
    args: argparse.Namespace, *, telemetry_hz: int, on_close: OnClose = "brake"
) -> Iterator[Hand]:
    """The Hand on ``--port``, or on an emulated board that lives as long as it does."""
    if args.port:
        with connect(args, telemetry_hz=telemetry_hz, on_close=on_close) as hand:
            yield hand
        return
    from utrf.emulator import EmulatedBoard

    with (
        EmulatedBoard(args.elf, realtime=True, pty=False) as board,
        Hand.emulated(board, telemetry_hz=telemetry_hz, on_close=on_close) as hand,
    ):
        yield hand
