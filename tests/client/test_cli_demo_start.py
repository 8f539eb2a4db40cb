"""`utrf demo` that cannot start (no firmware) keeps the previous run's files."""

from __future__ import annotations

from pathlib import Path

import pytest

from utrf.cli import main


def test_demo_without_firmware_keeps_the_last_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "demo"
    out.mkdir()
    kept = [out / "pose-01-open.png", out / "trajectories.png", out / "telemetry.csv"]
    for f in kept:
        f.write_bytes(b"the previous run")
    missing = tmp_path / "no.elf"
    argv = ["demo", "--out", str(out), "--elf", str(missing), "--no-live"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"utrf demo: error: firmware ELF {missing} not found"
    assert all(f.read_bytes() == b"the previous run" for f in kept)
