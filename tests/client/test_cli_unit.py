"""The CLI without a board: `utrf poses`, `utrf flash` (the avrdude command it runs, with a
stand-in avrdude), and the errors and exit codes of the hand commands before they connect."""

from __future__ import annotations

import json
import math
import os
import stat
import sys
from pathlib import Path

import pytest

from utrf.cli import main
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary

HAND = HandGeometry.default()


@pytest.fixture(autouse=True)
def no_user_poses(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("UTRF_POSES", str(tmp_path / "none.toml"))  # not the developer's own


def test_poses_lists_the_library(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["poses"]) == 0
    out = capsys.readouterr().out
    for name in PoseLibrary.load(include_user=False):
        assert name in out
    assert "degrees" in out


def test_poses_json_is_si_and_reads_user_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    user = tmp_path / "mine.toml"
    user.write_text('[pose.vulcan]\ndescription = "live long"\nflexion = { ring = 0.5 }\n')
    monkeypatch.setenv("UTRF_POSES", str(user))
    extra = tmp_path / "extra.toml"
    extra.write_text("[pose.shaka]\nflexion = { thumb = 0.1 }\n")  # replaces the built-in
    assert main(["poses", "--json", "--poses", str(extra)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["vulcan"]["description"] == "live long"
    ring = HAND.fingers[3].geometry
    expected = 0.5 * math.pi / 2 * ring.guide_radii_m[0] / ring.guide_radii_m[1]
    assert data["vulcan"]["theta2_rad"]["ring"] == pytest.approx(expected)
    assert data["shaka"]["source"] == str(extra)
    assert data["shaka"]["theta2_rad"]["index"] == 0.0
    assert data["grasp-egg"]["grasp"]["effort"] == pytest.approx(0.4)


def test_a_bad_pose_file_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[pose.claw]\nflexion = { index = 1.7 }\n")
    assert main(["poses", "--poses", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "'claw'" in err and "flexion.index = 1.7" in err


def test_pose_refuses_an_unknown_pose_before_connecting(capsys) -> None:
    # nothing listens on port 9: it would be exit 3 had it tried to connect
    assert main(["pose", "vulcan", "--port", "socket://127.0.0.1:9"]) == 2
    assert "no pose named 'vulcan'" in capsys.readouterr().err


def test_pose_without_a_board_is_a_link_error(capsys) -> None:
    assert main(["pose", "shaka", "--port", "socket://127.0.0.1:9", "--boot-wait", "0"]) == 3
    assert "cannot open 'socket://127.0.0.1:9'" in capsys.readouterr().err


def test_monitor_refuses_a_bad_rate(capsys) -> None:
    assert main(["monitor", "--port", "socket://127.0.0.1:9", "--rate", "1001"]) == 2
    assert "--rate must lie in 1..1000" in capsys.readouterr().err


# --- flash ------------------------------------------------------------------------------


def _hex(path: Path, records: list[str] | None = None) -> Path:
    lines = records or [
        ":100000000C9434000C9446000C9446000C9446006A",
        ":00000001FF",
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def _fake_avrdude(tmp_path: Path, exit_code: int) -> Path:
    """A stand-in avrdude that records its arguments."""
    script = tmp_path / "avrdude"
    script.write_text(
        f"#!{sys.executable}\nimport json, sys\n"
        f"open({str(tmp_path / 'args.json')!r}, 'w').write(json.dumps(sys.argv[1:]))\n"
        f"sys.exit({exit_code})\n"
    )
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return script


def test_flash_dry_run_prints_the_avrdude_command(tmp_path: Path, capsys) -> None:
    hex_file = _hex(tmp_path / "fw.hex")
    avrdude = _fake_avrdude(tmp_path, 0)
    argv = ["flash", "--port", "/dev/ttyACM9", "--hex", str(hex_file), "--dry-run"]
    assert main([*argv, "--avrdude", str(avrdude)]) == 0
    out = capsys.readouterr().out
    expected = (
        f"{avrdude} -p atmega2560 -c wiring -P /dev/ttyACM9 -b 115200 -D -U flash:w:{hex_file}:i"
    )
    assert out.startswith(expected) and "16 bytes" in out
    assert not (tmp_path / "args.json").exists()  # a dry run runs nothing


@pytest.mark.parametrize(("code", "exit_code"), [(0, 0), (1, 1)])
def test_flash_runs_avrdude(tmp_path: Path, code: int, exit_code: int, capsys) -> None:
    hex_file = _hex(tmp_path / "fw.hex")
    avrdude = _fake_avrdude(tmp_path, code)
    port = os.devnull  # a path that exists, standing in for the serial port
    argv = ["flash", "--port", port, "--hex", str(hex_file), "--avrdude", str(avrdude)]
    assert main([*argv, "--programmer", "stk500v2", "--no-sync-check"]) == exit_code
    args = json.loads((tmp_path / "args.json").read_text())
    assert args == [
        "-p", "atmega2560", "-c", "stk500v2", "-P", port, "-b", "115200", "-D",
        "-U", f"flash:w:{hex_file}:i",
    ]  # fmt: skip
    if code:
        assert "avrdude failed (exit 1)" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("records", "message"),
    [
        (None, "no HEX file at"),
        ([":100000000C9434000C9446000C9446000C9446006B", ":00000001FF"], ":1: checksum error"),
        (["0C9434000C94", ":00000001FF"], "must start with ':'"),
        ([":100000000C9434000C9446000C9446000C9446006A"], "no end-of-file record"),
    ],
    ids=["missing", "checksum", "not-hex", "cut-short"],
)
def test_flash_refuses_a_bad_hex(tmp_path: Path, records, message: str, capsys) -> None:
    path = tmp_path / "fw.hex"
    if records is not None:
        _hex(path, records)
    assert main(["flash", "--port", "/dev/ttyACM0", "--hex", str(path), "--dry-run"]) == 2
    assert message in capsys.readouterr().err


def test_flash_without_avrdude_says_how_to_get_it(tmp_path: Path, capsys) -> None:
    hex_file = _hex(tmp_path / "fw.hex")
    argv = ["flash", "--port", "/dev/ttyACM0", "--hex", str(hex_file), "--dry-run"]
    assert main([*argv, "--avrdude", str(tmp_path / "no-avrdude")]) == 2
    err = capsys.readouterr().err
    assert "avrdude not found" in err and "apt-get install avrdude" in err
