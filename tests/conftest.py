"""Fixtures shared by every suite: builds brought up to date with make.

``make test`` builds everything first; a suite run on its own (``pytest tests/e2e``) builds
what it needs here, and fails with make's message if it cannot.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FIRMWARE_ELF = REPO / "build" / "firmware" / "utrf.elf"

# The suite runs a worker per core (pytest-xdist): each twin on one thread, as campaign workers
# (tests/emulator/test_emu_twin_threads.py asks for two where it compares them).
os.environ.setdefault("UTRF_TWIN_THREADS", "1")


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
def make() -> Callable[..., None]:
    """``make(*targets)``: bring these targets up to date (quick when they are)."""
    return _make


@pytest.fixture(scope="session")
def firmware_elf() -> Path:
    """The real firmware, as `make firmware` builds it, and the emulator's library."""
    _make("emulator", "firmware")
    return FIRMWARE_ELF
