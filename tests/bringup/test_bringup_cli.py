"""``utrf bringup`` over a served emulated board (the wall clock, as on a real hand), and
``utrf emulate --build`` refusing a build it cannot make."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from utrf.cli import main
from utrf.emulator import BuildFaults, EmulatedBoard


def test_emulate_refuses_a_bad_build_naming_the_kinds(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "--build", "nonsense:1", "--duration", "0.1", "--no-pty"]) == 2
    err = capsys.readouterr().err
    assert "nonsense:1" in err and "swap-leads" in err


@pytest.mark.slow
def test_bringup_command_finds_swapped_leads(
    firmware_elf: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    build = BuildFaults.parse(["swap-leads:index"])
    with EmulatedBoard(firmware_elf, realtime=True, speed=1.0, pty=False, build=build) as board:
        code = main(
            ["bringup", "--port", board.url or "", "--finger", "index", "--upto", "wiring",
             "--yes", "--out", str(tmp_path), "--boot-wait", "1"]
        )  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0, out
    assert "motor_invert = 1" in out
    measured = json.loads((tmp_path / "measurements.json").read_text())
    assert [f["kind"] for f in measured["fingers"][0]["findings"]] == ["leads-swapped"]
    assert (tmp_path / "report.md").read_text().startswith("# Bring-up report")
