"""Shared set-up for the emulator's tests: the harness library and the two ELFs they run.

``make test`` builds everything first; run on their own (``pytest tests/emulator``) these
fixtures bring the builds up to date with make (``make`` and ``firmware_elf`` are in
tests/conftest.py), and fail with make's message if it cannot.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FIXTURE_ELF = REPO / "build" / "emulator" / "fixture.elf"


@pytest.fixture(scope="session")
def fixture_elf(make: Callable[..., None]) -> Path:
    """The harness's own test program (tests/emulator/fixtures/fixture.c), and the library."""
    make("emulator")
    return FIXTURE_ELF
