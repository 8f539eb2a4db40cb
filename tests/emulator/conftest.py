"""Shared set-up for the emulator's tests: the harness library and the two ELFs they run.

``make test`` builds everything first; run on their own (``pytest tests/emulator``) these
fixtures bring the builds up to date with make, and fail with make's message if it cannot.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FIXTURE_ELF = REPO / "build" / "emulator" / "fixture.elf"
FIRMWARE_ELF = REPO / "build" / "firmware" / "utrf.elf"


def _make(*targets: str) -> None:
    proc = subprocess.run(
        ["make", "-s", "--no-print-directory", *targets],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode:
        pytest.fail(f"`make {' '.join(targets)}` failed:\n{proc.stdout}\n{proc.stderr}")


@pytest.fixture(scope="session")
def fixture_elf() -> Path:
    """The harness's own test program (tests/emulator/fixtures/fixture.c), and the library."""
    _make("emulator")
    return FIXTURE_ELF


@pytest.fixture(scope="session")
def firmware_elf() -> Path:
    """The real firmware, as `make firmware` builds it."""
    _make("emulator", "firmware")
    return FIRMWARE_ELF
