"""`utrf flash` (and `make flash`, which calls it) without a board: fails fast and clearly.

No port: exit 2 at once. A port where nothing answers the bootloader's sign-on: exit 1 within
the sync timeout, before avrdude (which would retry for 30 s) runs. A port where a bootloader
answers: avrdude runs. The ports are ptys, with a thread as the board at the other end.
"""

from __future__ import annotations

import os
import pty
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import pytest
from test_cli_unit import _fake_avrdude, _hex

from utrf.cli import main
from utrf.cli.flash import CMD_SIGN_ON, stk500v2_message

REPO = Path(__file__).resolve().parents[2]


class FakePort:
    """A pty; ``answer`` makes the far end reply to a sign-on as the MEGA's bootloader does."""

    def __init__(self, answer: bool) -> None:
        self.master, slave = pty.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        self.answer = answer
        self.heard = b""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import select

        while not self._stop.is_set():
            if not select.select([self.master], [], [], 0.02)[0]:
                continue
            try:
                data = os.read(self.master, 256)
            except OSError:
                continue  # nobody has the slave open
            self.heard += data
            if self.answer and len(data) >= 7 and data[5] == CMD_SIGN_ON:
                body = bytes([CMD_SIGN_ON, 0x00, 8]) + b"AVRISP_2"
                os.write(self.master, stk500v2_message(data[1], body))

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        os.close(self.master)


def test_missing_port_fails_at_once(tmp_path: Path, capsys) -> None:
    hex_file = _hex(tmp_path / "fw.hex")
    avrdude = _fake_avrdude(tmp_path, 0)
    t0 = time.monotonic()
    code = main(["flash", "--port", "/dev/ttyACM97", "--hex", str(hex_file),
                 "--avrdude", str(avrdude)])  # fmt: skip
    assert code == 2 and time.monotonic() - t0 < 1.0
    assert "no serial port /dev/ttyACM97: is the MEGA plugged in?" in capsys.readouterr().err
    assert not (tmp_path / "args.json").exists()


def test_a_silent_board_is_a_clear_error_within_the_sync_timeout(tmp_path: Path, capsys) -> None:
    hex_file = _hex(tmp_path / "fw.hex")
    avrdude = _fake_avrdude(tmp_path, 0)
    port = FakePort(answer=False)
    try:
        t0 = time.monotonic()
        code = main(["flash", "--port", port.path, "--hex", str(hex_file),
                     "--avrdude", str(avrdude), "--sync-timeout", "1.5"])  # fmt: skip
        took = time.monotonic() - t0
    finally:
        port.close()
    assert code == 1 and 1.4 < took < 3.0
    err = capsys.readouterr().err
    assert f"no STK500v2 bootloader answered on {port.path} within 1.5 s" in err
    assert stk500v2_message(1, bytes([CMD_SIGN_ON])) in port.heard  # it did ask
    assert not (tmp_path / "args.json").exists()  # avrdude never ran


def test_a_board_whose_bootloader_answers_is_flashed(tmp_path: Path, capsys) -> None:
    hex_file = _hex(tmp_path / "fw.hex")
    avrdude = _fake_avrdude(tmp_path, 0)
    port = FakePort(answer=True)
    try:
        code = main(["flash", "--port", port.path, "--hex", str(hex_file),
                     "--avrdude", str(avrdude)])  # fmt: skip
    finally:
        port.close()
    assert code == 0
    assert f"bootloader on {port.path}: AVRISP_2" in capsys.readouterr().out
    assert (tmp_path / "args.json").exists()


@pytest.mark.parametrize("port", ["", "/dev/ttyACM97"])
def test_make_flash_fails_fast_and_clearly(port: str) -> None:
    t0 = time.monotonic()
    proc = subprocess.run(
        ["make", "--no-print-directory", "flash", f"PORT={port}"],
        cwd=REPO, capture_output=True, text=True, check=False, timeout=120,
    )  # fmt: skip
    assert proc.returncode != 0
    if port:
        assert "no serial port /dev/ttyACM97: is the MEGA plugged in?" in proc.stderr
        assert time.monotonic() - t0 < 60  # the set-up check and the HEX, not a hang
    else:
        assert "usage: make flash PORT=/dev/ttyACM0" in proc.stderr
    assert sys.executable
