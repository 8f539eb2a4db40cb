"""``utrf emulate``: serves until interrupted, prints where to connect and its real-time factor,
takes fault injection from its options and from stdin, refuses bad input."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import serial

from utrf.cli import build_parser, main
from utrf.cli.emulate import build_board
from utrf.emulator import BoardProcess, EmulatorError


def test_serves_until_interrupted(fixture_elf: Path, tmp_path: Path) -> None:
    url_file = tmp_path / "urls"
    cmd = [sys.executable, "-m", "utrf", "emulate", "--elf", str(fixture_elf), "--json"]
    cmd += ["--url-file", str(url_file), "--status-interval", "0.2"]
    proc = subprocess.Popen(
        cmd,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 20
        while not url_file.exists():
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            assert time.monotonic() < deadline, "no URL file"
            time.sleep(0.05)
        url, pty = url_file.read_text().split()
        assert url.startswith("socket://127.0.0.1:") and pty.startswith("/dev/pts/")
        with serial.serial_for_url(url, timeout=5.0) as port:
            assert port.readline() == b"boot 2\n"  # the client's connection reset it
            assert proc.stdin is not None
            proc.stdin.write("unplug 2 1.5\nnoise 0\n")
            proc.stdin.flush()
            time.sleep(0.3)
            port.write(b"a\n")
            reading = port.readline().split()
            assert int(reading[3]) == round(1.5 * 1024 / 5)  # ADC2: the unplugged input (307.2)
        time.sleep(0.3)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    events = [json.loads(line) for line in out.splitlines()]
    assert events[0]["event"] == "serving" and events[0]["url"] == url
    assert any(e["event"] == "unplugged" for e in events)
    assert any(e["event"] == "status" for e in events)
    last = events[-1]
    assert last["event"] == "stopped"
    assert 0 < last["realtime_factor"] <= 1.01  # paced: never ahead of the wall clock
    assert last["clients"] == []
    port_number = int(url.rsplit(":", 1)[1])
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port_number), timeout=1.0)


def test_board_process(fixture_elf: Path) -> None:
    board = BoardProcess(fixture_elf, pty=False)
    try:
        assert board.url is not None and board.pty_path is None
        with serial.serial_for_url(board.url, timeout=5.0) as port:
            assert port.readline() == b"boot 2\n"
            assert board.command("unplug 3 2.0")["event"] == "unplugged"
            time.sleep(0.05)
            port.write(b"a\n")
            assert int(port.readline().split()[4]) == 410  # 2 V: 409.6 LSB, the nearest code
        state = board.state()
        assert len(state["theta2_rad"]) == 5 and state["adc_volts"][3] == 2.0
        assert board.status()["clients"] == []
        with pytest.raises(EmulatorError, match="refused"):
            board.command("unplug 9")
    finally:
        final = board.close()
    assert not board.alive
    assert final is not None and final["event"] == "stopped" and final["sim_time_s"] > 0
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", int(board.url.rsplit(":", 1)[1])), timeout=1.0)


def test_board_process_bad_elf(tmp_path: Path) -> None:
    with pytest.raises(EmulatorError, match="not found"):
        BoardProcess(tmp_path / "missing.elf")


def test_fault_options(fixture_elf: Path) -> None:
    argv = ["emulate", "--elf", str(fixture_elf), "--no-pty", "--block", "1:30"]
    argv += ["--obstacle", "middle:45", "--unplug-encoder", "3:4.5", "--unplug-encoder", "4"]
    argv += ["--line-corrupt", "1", "--line-direction", "to_host"]
    args = build_parser().parse_args(argv)
    board = build_board(args)
    try:
        blocks = board.plant.blocks / board.plant.R[:, 1:2]  # as Joint-2 angles
        np.testing.assert_allclose(blocks[1], np.radians([30, 30]))
        assert blocks[2, 1] == pytest.approx(np.radians(45)) and blocks[2, 0] < -1.0
        board.run_for(0.01)  # the next exchanges carry the plant's new voltages
        assert board.adc_volts[3] == 4.5 and board.adc_volts[4] == 0.0
        before = board.stats["tx_corrupted"]
        board.reset()
        board.run_for(0.05)
        assert board.stats["tx_corrupted"] - before == 7  # "boot 2\n", every byte
        assert board.stats["rx_corrupted"] == 0
    finally:
        board.close()


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--elf", "/nonexistent.elf"], "not found"),
        (["--duration", "-1"], "--duration"),
        (["--speed", "0"], None),
        (["--obstacle", "2"], None),
        (["--line-drop", "2"], None),
        (["--block", "pinky:10"], None),
    ],
)
def test_bad_input_exits_2(
    fixture_elf: Path, capsys: pytest.CaptureFixture[str], argv: list[str], needle: str | None
) -> None:
    if "--elf" not in argv:
        argv = ["--elf", str(fixture_elf), *argv]
    try:
        code = main(["emulate", "--no-pty", *argv])
    except SystemExit as exc:  # argparse's own refusal
        code = exc.code
    assert code == 2
    if needle:
        assert needle in capsys.readouterr().err


@pytest.mark.parametrize(
    ("line", "said"), [("hang", "hung: the firmware\n"), ("hang cli", "with interrupts off\n")]
)
def test_the_hang_command_ends_in_a_watchdog_reset(
    firmware_elf: Path, line: str, said: str
) -> None:
    import io

    from utrf.cli.emulate import _command, _Printer
    from utrf.emulator import EmulatedBoard

    out = io.StringIO()
    with EmulatedBoard(firmware_elf, realtime=False, seed=3) as board:
        board.run_for(0.1)
        resets = board.stats["watchdog_resets"]
        say = _Printer(out, as_json=False)
        assert _command(board, "hang now", say)  # refused: the firmware runs on
        board.run_for(0.2)
        assert board.stats["watchdog_resets"] == resets
        assert _command(board, line, say)
        board.run_for(0.2)  # the watchdog's period is 0.128 s
        assert board.stats["watchdog_resets"] == resets + 1
        assert board.reset_cause == "watchdog"
    refusal, hung = out.getvalue().splitlines(keepends=True)
    assert refusal.startswith("error: hang:")
    assert hung.startswith("hung: the firmware") and hung.endswith(said)
