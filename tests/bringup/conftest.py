"""The bring-up on driven emulated boards (simulated time): ``built(*faults)`` is a board
built with those faults (``utrf.emulator.build_faults``) and a Hand on it."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from bringup_helpers import Built

from utrf.emulator import BuildFaults, EmulatedBoard
from utrf.hand import Hand


@pytest.fixture
def built(firmware_elf: Path, make: Callable[..., None]) -> Built:
    make("emulator")

    @contextmanager
    def open_(*faults: str, seed: int = 0, **kw: object) -> Iterator[tuple[EmulatedBoard, Hand]]:
        build = BuildFaults.parse(list(faults))
        board = EmulatedBoard(firmware_elf, realtime=False, seed=seed, build=build, **kw)
        with board, Hand.emulated(board) as hand:
            yield board, hand

    return open_
