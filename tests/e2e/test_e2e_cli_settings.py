"""Every setting from the shell (issue 22): `utrf gains|limits|motion|safety|hardware get/set`,
`jog`, `mode`, `zero`, `clear-faults`, `eeprom`, `config backup/restore`, through the real CLI
on the emulated board's pty; bad input is refused naming the field and its range before
anything is sent (the board sees no connection). And the errors that name what happened: not
a UTRF board, the emulator already has a host attached, no answer."""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from utrf.cli import main
from utrf.emulator import EmulatedBoard
from utrf.hand import Hand


@pytest.fixture(scope="module")
def board(firmware_elf: Path) -> Iterator[EmulatedBoard]:
    with EmulatedBoard(firmware_elf, realtime=True, pty=True, seed=6) as b:
        assert b.pty_path is not None
        yield b


def utrf(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's own refusal
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def on(board: EmulatedBoard, *argv: str) -> list[str]:
    return [*argv, "--port", str(board.pty_path)]


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["gains", "set", "index", "kp=-1"], "gains.kp = -1 1/deg is outside its range 0 .."),
        (["limits", "set", "index", "theta2_max=200"], "-183.346 .. 183.346 deg (-3.2 .. 3.2 rad)"),
        (["motion", "set", "ring", "max_speed=abc"], "motion.max_speed must be a number"),
        (["safety", "set", "heartbeat_timeout=20"], "safety.heartbeat_timeout = 20 s is outside"),
        (["safety", "set", "safe_action=explode"], "one of ['hold', 'coast']"),
        (["hardware", "set", "thumb", "encoder_invert=2"], "hardware.encoder_invert = 2 is"),
        (["gains", "set", "index", "zz=1"], "gains has no field 'zz'; its fields are ['kp'"),
        (["gains", "set", "pinky", "kp=1"], "no finger 'pinky'"),
        (["jog", "index"], "one of the arguments --to --by is required"),
        (["mode", "duty", "index"], "duty needs --duty in -1..1"),
    ],
)
def test_bad_input_is_refused_before_anything_is_sent(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str], argv: list[str], needle: str
) -> None:
    connections = board.stats["clients"]
    code, _, err = utrf(capsys, *on(board, *argv))
    assert code == 2 and needle in err
    assert board.stats["clients"] == connections  # it never connected


def test_settings_get_and_set_in_degrees(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = utrf(capsys, *on(board, "limits", "set", "index", "theta2_max=80"))
    assert code == 0 and "index limits.theta2_max: " in out and "-> 80 deg" in out
    code, out, _ = utrf(capsys, *on(board, "limits", "get", "index", "--json"))
    assert code == 0 and '"theta2_max": 1.396263' in out  # SI in JSON
    code, out, _ = utrf(capsys, *on(board, "limits", "get", "index", "ring"))
    assert "theta2_max [deg]" in out and " 80 " in out and "index" in out and "ring" in out
    code, _, err = utrf(capsys, *on(board, "jog", "index", "--to", "85"))
    assert code == 2 and "outside its Joint-2 limits" in err and "80.0] deg" in err
    code, out, _ = utrf(capsys, *on(board, "safety", "set", "safe_action=coast"))
    assert code == 0 and "board safety.safe_action: hold -> coast" in out
    code, out, _ = utrf(capsys, *on(board, "safety", "get"))
    assert "coast" in out and "heartbeat_timeout [s]" in out


@pytest.mark.slow
def test_jog_mode_zero_clear_faults_and_eeprom(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = utrf(capsys, *on(board, "jog", "middle", "--to", "30"))
    assert code == 0, err
    assert abs(board.theta2[2] - math.radians(30)) < math.radians(2.5)
    code, out, err = utrf(capsys, *on(board, "jog", "middle", "--by", "-10"))
    assert code == 0 and abs(board.theta2[2] - math.radians(20)) < math.radians(2.5)
    code, _, err = utrf(capsys, *on(board, "zero", "middle"))  # held in POSITION: refused
    assert code == 1 and "middle is in POSITION" in err
    code, out, _ = utrf(capsys, *on(board, "mode", "brake", "middle"))
    assert code == 0 and "middle: brake" in out
    code, out, _ = utrf(capsys, *on(board, "zero", "middle"))
    assert code == 0 and "zeroed: middle" in out
    with Hand.connect(str(board.pty_path), reset=False, on_close="hold") as hand:
        assert abs(hand.state()["middle"].theta2) < 0.02  # the present angle is now 0
    code, out, _ = utrf(capsys, *on(board, "mode", "duty", "ring", "--duty", "0.3", "--for", "0.3"))
    assert code == 0 and "ring: brake, after the duty" in out
    code, out, _ = utrf(capsys, *on(board, "clear-faults"))
    assert code == 0 and "cleared:" in out
    code, out, _ = utrf(capsys, *on(board, "eeprom", "save"))
    assert code == 0 and "saved" in out
    code, out, _ = utrf(capsys, *on(board, "mode", "position", "index"))
    assert code == 0 and "index: position" in out and "index" in out
    code, _, err = utrf(capsys, *on(board, "eeprom", "load"))
    assert code == 1 and "index is in POSITION: loading needs every finger idle" in err
    assert utrf(capsys, *on(board, "mode", "brake"))[0] == 0
    code, out, _ = utrf(capsys, *on(board, "eeprom", "load", "--defaults"))
    assert code == 0 and "the firmware's defaults" in out
    code, out, _ = utrf(capsys, *on(board, "hardware", "get", "middle", "--json"))
    assert '"encoder_offset": 3.14159' in out  # the zero is gone with the defaults


@pytest.mark.slow
def test_config_backup_restore_round_trips(
    board: EmulatedBoard, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    assert utrf(capsys, *on(board, "config", "backup", str(a)))[0] == 0
    text = a.read_text()
    assert "[finger.little.motion]" in text and "[safety]" in text and "# rad" in text
    assert utrf(capsys, *on(board, "gains", "set", "thumb", "kd=0.01"))[0] == 0
    assert utrf(capsys, *on(board, "safety", "set", "heartbeat_timeout=0.8"))[0] == 0
    code, out, _ = utrf(capsys, *on(board, "config", "restore", str(a), "--dry-run"))
    assert code == 0 and "thumb gains.kd: 0.01 s/deg -> " in out
    assert "board safety.heartbeat_timeout: 0.8 s -> 0.5 s" in out and "dry run" in out
    code, out, _ = utrf(capsys, *on(board, "safety", "get", "--json"))
    assert '"heartbeat_timeout": 0.8' in out  # the dry run changed nothing
    code, out, _ = utrf(capsys, *on(board, "config", "restore", str(a)))
    assert code == 0 and "2 settings changed" in out
    assert utrf(capsys, *on(board, "config", "backup", str(b)))[0] == 0
    assert b.read_text() == text  # exactly what was backed up


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ("[finger.index.limits]\ntheta2_max = 4.0\n", "[finger.index.limits]: limits.theta2_max"),
        ("[finger.index.gains]\nkq = 1.0\n", "gains has no field 'kq'"),
        ("[finger.pinky.gains]\nkp = 1.0\n", "no finger 'pinky'"),
        ("[safety]\nsafe_action = 3\n", "safety.safe_action must be one of"),
        ("[gains]\nkp = 1\n", "unknown table [gains]"),
        ("kp = = 1\n", "cannot read it as TOML"),
    ],
)
def test_a_bad_config_file_is_refused_before_anything_is_sent(
    board: EmulatedBoard,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    content: str,
    needle: str,
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(content)
    connections = board.stats["clients"]
    code, _, err = utrf(capsys, *on(board, "config", "restore", str(path)))
    assert code == 2 and str(path) in err and needle in err
    assert board.stats["clients"] == connections


def test_a_second_host_is_turned_away(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    with Hand.connect(str(board.pty_path), reset=False, on_close="hold"):
        assert board.clients == {"pty": True, "tcp": False}
        code, _, err = utrf(capsys, "safety", "get", "--port", str(board.url))
        assert code == 4 and "the emulator already has a host attached" in err
        assert board.clients == {"pty": True, "tcp": False}
    assert utrf(capsys, *on(board, "safety", "get"))[0] == 0  # free again


def _server(reply: bytes | None) -> str:
    srv = socket.create_server(("127.0.0.1", 0))

    def run() -> None:
        conn, _ = srv.accept()
        if reply is None:
            time.sleep(15)  # a silent device
        else:
            conn.sendall(reply)
            conn.settimeout(0.2)
            end = time.monotonic() + 1.0
            while time.monotonic() < end:  # read what the host sends (unread: a reset)
                try:
                    if not conn.recv(4096):
                        break
                except TimeoutError:
                    pass
        conn.close()
        srv.close()

    threading.Thread(target=run, daemon=True).start()
    return f"socket://127.0.0.1:{srv.getsockname()[1]}"


def test_a_server_that_is_not_a_hand_is_named(capsys: pytest.CaptureFixture[str]) -> None:
    url = _server(b"SSH-2.0-OpenSSH_9.2\r\n")
    code, _, err = utrf(capsys, "safety", "get", "--port", url, "--boot-wait", "0")
    assert code == 3
    assert f"not a UTRF board (no identity answer on {url}): it sent 21 bytes" in err
    assert "SSH-2.0" in err and "closed the line" in err


@pytest.mark.slow
def test_a_silent_device_gets_no_answer(capsys: pytest.CaptureFixture[str]) -> None:
    url = _server(None)
    code, _, err = utrf(capsys, "safety", "get", "--port", url, "--boot-wait", "0")
    assert code == 3
    assert f"no answer on {url} to identify in " in err
    assert "is the board powered, is it the right port, is another program using it?" in err
