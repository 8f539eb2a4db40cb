"""Shared set-up for the emulator's tests: the harness library and the two ELFs they run.

``make test`` builds everything first; run on their own (``pytest tests/emulator``) these
fixtures bring the builds up to date with make (``make`` and ``firmware_elf`` are in
tests/conftest.py), and fail with make's message if it cannot.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from emu_helpers import QUIET

from utrf.emulator import EmulatedBoard

REPO = Path(__file__).resolve().parents[2]
FIXTURE_ELF = REPO / "build" / "emulator" / "fixture.elf"


@pytest.fixture(scope="session")
def fixture_elf(make: Callable[..., None]) -> Path:
    """The harness's own test program (tests/emulator/fixtures/fixture.c), and the library."""
    make("emulator")
    return FIXTURE_ELF


@pytest.fixture
def board(firmware_elf: Path) -> Iterator[EmulatedBoard]:
    """The real firmware on a driven board with the quiet plant (a test module may define its
    own ``board``)."""
    with EmulatedBoard(firmware_elf, realtime=False, plant_params=QUIET) as b:
        yield b
