"""Fixtures of the reliability suite: the real firmware on a driven emulated board, a Hand on
it, and where the campaigns' figures go (build/reliability/*.json, which
tools/reliability_doc.py turns into docs/reliability.md)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand


@pytest.fixture
def board(firmware_elf: Path) -> Iterator[EmulatedBoard]:
    with EmulatedBoard(firmware_elf, realtime=False, seed=1) as b:
        yield b


@pytest.fixture
def hand(board: EmulatedBoard) -> Iterator[Hand]:
    with Hand.emulated(board) as h:
        yield h
