"""End-to-end fixtures: the real firmware ELF on the emulated board, driven by a Hand.

Most tests drive the board (``realtime=False``) through a Hand over a SimLink: simulated
time, as fast as the machine goes, the same on every run. The tests of the real-time path
(a Hand over ``socket://``, the CLI, the demo) serve the board paced to the wall clock.
``make test`` builds everything first; run alone, ``firmware_elf`` (tests/conftest.py) brings
the builds up to date.
"""

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
