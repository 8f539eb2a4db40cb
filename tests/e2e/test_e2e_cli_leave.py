"""Leaving the hand (issue 22): `utrf pose` says goodbye, so a pose left held latches no
HOST_TIMEOUT and the next command takes over; a command killed without it still latches
HOST_TIMEOUT; Ctrl-C holds the fingers where they are, says so and exits 130. Through the
real CLI, on the emulated board's pty (which can be reopened without a reset)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from utrf.cli import main
from utrf.emulator import EmulatedBoard
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary


@pytest.fixture
def board(firmware_elf: Path) -> Iterator[EmulatedBoard]:
    with EmulatedBoard(firmware_elf, realtime=True, pty=True, seed=4) as b:
        assert b.pty_path is not None
        yield b


@pytest.fixture(autouse=True)
def no_user_poses(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("UTRF_POSES", str(tmp_path / "none.toml"))


def utrf(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_a_pose_left_held_is_taken_over_without_a_fault(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    pty = str(board.pty_path)
    code, out, _ = utrf(capsys, "pose", "shaka", "--port", pty, "--duration", "0.4")
    assert code == 0 and "left in hold" in out
    time.sleep(1.0)  # twice the board's heartbeat timeout, the host gone
    goal = PoseLibrary.load(include_user=False)["shaka"].theta2(HandGeometry.default())
    np.testing.assert_allclose(board.theta2, goal, atol=0.05)  # held
    code, out, err = utrf(capsys, "pose", "fist", "--port", pty, "--no-reset", "--duration", "0.4")
    assert code == 0, err  # a latched HOST_TIMEOUT would refuse the move (exit 1)
    code, out, _ = utrf(capsys, "clear-faults", "--port", pty)
    assert code == 0 and "cleared: nothing was latched" in out


@pytest.mark.slow
def test_a_command_killed_without_goodbye_latches_host_timeout(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    pty = str(board.pty_path)
    cmd = [sys.executable, "-m", "utrf", "pose", "fist", "--port", pty, "--duration", "3"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("moving to fist")
        assert board.wait_until(lambda b: b.theta2[1] > 0.3, timeout=30.0)  # under way
        proc.kill()  # no goodbye
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    time.sleep(1.0)
    code, _, err = utrf(capsys, "pose", "open", "--port", pty, "--no-reset", "--duration", "0.4")
    assert code == 1 and "HOST_TIMEOUT" in err
    code, out, _ = utrf(capsys, "clear-faults", "--port", pty)
    assert code == 0 and "HOST_TIMEOUT" in out.split("cleared:", 1)[1]


@pytest.mark.slow
def test_ctrl_c_holds_the_fingers_where_they_are(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupt_once_moving() -> None:  # (in COAST the fingers droop: negative angles)
        if board.wait_until(lambda b: b.theta2[1] > 0.4, timeout=30.0):  # the index flexes
            signal.pthread_kill(threading.main_thread().ident or 0, signal.SIGINT)

    threading.Thread(target=interrupt_once_moving, daemon=True).start()
    argv = ["pose", "fist", "--port", str(board.pty_path), "--duration", "3"]
    code, out, err = utrf(capsys, *argv)
    assert code == 130
    assert "interrupted; held where they were (POSITION at the measured angle)" in err
    assert "POSITION" in out.splitlines()[-1]  # the state it left, printed
    time.sleep(1.0)  # past the heartbeat timeout: held, nothing latched
    held = board.theta2.copy()
    goal = PoseLibrary.load(include_user=False)["fist"].theta2(HandGeometry.default())
    assert np.abs(held - goal).max() > 0.3  # mid-path, not finished
    time.sleep(0.3)
    np.testing.assert_allclose(board.theta2, held, atol=0.02)
    code, out, _ = utrf(capsys, "clear-faults", "--port", str(board.pty_path))
    assert code == 0 and "nothing was latched" in out
