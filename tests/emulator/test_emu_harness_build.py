"""The harness records what it was built with (build/emulator/built-with.txt): built without
MuJoCo's headers (no mujoco for the Python make asks), it is rebuilt with them once they are
there; then make has nothing to do. (A fresh clone's one-invocation `make setup firmware
emulator` is tests/packaging/test_fresh_clone.py.)"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def _make(build: Path, *extra: str) -> str:
    r = subprocess.run(
        ["make", "--no-print-directory", f"BUILD={build}", "SETUP_DONE=1", *extra,
         f"{build}/emulator/libutrf_sim.so"],
        cwd=REPO, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return r.stdout


@pytest.mark.slow
def test_a_harness_built_without_mujoco_is_rebuilt_once_it_is_there(tmp_path: Path) -> None:
    out = _make(tmp_path, "PY=/bin/false")  # a Python that has no mujoco
    assert "without MuJoCo" in out and "-DUTRF_WITH_MUJOCO" not in out
    assert "mujoco_include=none" in (tmp_path / "emulator" / "built-with.txt").read_text()
    out = _make(tmp_path, f"PY={sys.executable}")
    assert "-DUTRF_WITH_MUJOCO" in out
    assert "mujoco_include=none" not in (tmp_path / "emulator" / "built-with.txt").read_text()
    assert " -shared " not in _make(tmp_path, f"PY={sys.executable}")  # up to date
