"""Bench runs' tests: the builds they need (``make test`` makes them first; run alone, these
fixtures bring them up to date with make and fail with its message)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FIRMWARE_ELF = REPO / "build" / "firmware" / "utrf.elf"


@pytest.fixture(scope="session")
def firmware_elf() -> Path:
    proc = subprocess.run(
        ["make", "-s", "--no-print-directory", "emulator", "firmware"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode:
        pytest.fail(f"`make emulator firmware` failed:\n{proc.stdout}\n{proc.stderr}")
    return FIRMWARE_ELF
