"""Connecting without a reset (issue 9 §5): a pose held by one connection is still held, the
fingers unmoved, when another connects with ``reset=False``; the emulated board models the
MEGA's DTR auto-reset on its pty as Linux drives a serial port's DTR."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from utrf.cli import main
from utrf.emulator import EmulatedBoard
from utrf.hand import Hand
from utrf.hand.serial_port import ResetModeError
from utrf.poses import PoseLibrary
from utrf.protocol import messages as M

LIBRARY = PoseLibrary.load(include_user=False)


@pytest.fixture
def board(firmware_elf: Path) -> Iterator[EmulatedBoard]:
    with EmulatedBoard(firmware_elf, realtime=True, pty=True, seed=3) as b:
        assert b.pty_path is not None
        yield b


def _pose_and_leave(board: EmulatedBoard, pose: str) -> np.ndarray:
    assert board.pty_path is not None
    with Hand.connect(board.pty_path, on_close="hold") as hand:  # a reset: the first open
        assert hand.identity.reset_cause == M.ResetCause.RESET_PIN
        hand.pose(pose, duration=0.4)
    return board.theta2.copy()


@pytest.mark.slow
def test_reconnect_without_reset_leaves_the_fingers_where_they_are(
    board: EmulatedBoard,
) -> None:
    _pose_and_leave(board, "point")
    resets = board.stats["resets"]
    time.sleep(0.5)  # disconnected: the board holds the pose on its own
    held = board.theta2.copy()
    assert board.pty_path is not None
    with Hand.connect(board.pty_path, reset=False, on_close="hold") as hand:
        st = hand.state()
        assert board.stats["resets"] == resets  # no reset
        assert hand.last_boot is None  # no boot frame was seen
        for f in st.fingers:  # taken over: still in closed loop, holding the pose
            assert f.mode == M.ControlMode.POSITION
        goal = LIBRARY["point"].theta2(hand.geometry)
        np.testing.assert_allclose(held, goal, atol=0.03)
        # the pose's targets, no fault: the first connection said goodbye
        np.testing.assert_allclose(st.target, goal, atol=0.03)
        assert all(f.faults == 0 for f in st.fingers)
        time.sleep(0.5)  # heartbeats flow; nothing moves
        # The hold dithers by a few encoder counts (0.0015 rad each) under the plant's noise;
        # a reset would put every finger in COAST, and the flexed ones would fall.
        np.testing.assert_allclose(board.theta2, held, atol=0.02)
        assert all(f.mode == M.ControlMode.POSITION for f in hand.state().fingers)
    assert board.stats["resets"] == resets


@pytest.mark.slow
def test_a_connection_with_reset_resets_even_after_a_no_reset_one(board: EmulatedBoard) -> None:
    _pose_and_leave(board, "fist")
    resets = board.stats["resets"]
    assert board.pty_path is not None
    with Hand.connect(board.pty_path, reset=False, on_close="hold"):
        pass
    assert board.stats["resets"] == resets
    with Hand.connect(board.pty_path) as hand:  # DTR dropped, then raised: the auto-reset
        assert board.stats["resets"] == resets + 1
        assert hand.identity.reset_cause == M.ResetCause.RESET_PIN
        assert all(f.mode == M.ControlMode.COAST for f in hand.state().fingers)


@pytest.mark.slow
def test_utrf_monitor_leaves_a_held_pose_alone(
    board: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    assert board.pty_path is not None
    argv = ["pose", "point", "--port", board.pty_path, "--then", "hold", "--duration", "0.4"]
    assert main(argv) == 0
    time.sleep(0.5)
    held = board.theta2.copy()
    resets = board.stats["resets"]
    argv = ["monitor", "--port", board.pty_path, "--duration", "1", "--every", "0.5"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("t=")]
    assert lines and all("COAST" not in line for line in lines)
    assert all(line.count("POSITION") == 5 for line in lines)
    assert board.stats["resets"] == resets
    np.testing.assert_allclose(board.theta2, held, atol=0.02)


def test_no_reset_over_tcp_is_refused_with_the_reason(board: EmulatedBoard) -> None:
    assert board.url is not None
    with pytest.raises(ResetModeError, match="socket:// carries no DTR line"):
        Hand.connect(board.url, reset=False)
