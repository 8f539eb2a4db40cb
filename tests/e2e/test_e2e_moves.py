"""Moves on the board's clock, on the real firmware and the emulated plant (simulated time):
the setpoint the board streams follows the minimum-jerk path of the duration it reported, a
path too fast for the finger is stretched and the reply says so, the feedforward keeps the
finger on the path, and the demo's poses are tracked within the goal (RMS 1 deg, worst 3 deg).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand, HandState
from utrf.hand.demo import DEFAULT_SEQUENCE
from utrf.hand.tracking import tracking
from utrf.protocol import messages as M
from utrf.trajectory import min_jerk_profile

INDEX = 1


def record(hand: Hand) -> list[HandState]:
    trace: list[HandState] = []
    hand.on_state(trace.append)
    return trace


def test_the_board_streams_its_path_and_stretches_what_the_finger_cannot_follow(
    hand: Hand,
) -> None:
    hand.set_telemetry(500)
    hand.move({INDEX: 0.0}, 0.3)
    trace = record(hand)
    result = hand.move({INDEX: 1.0}, 0.5)
    # 1 rad in 0.5 s asks for 3.75 rad/s at mid-path; the finger's limit is 1.2 rad/s
    assert result.stretched == ("index",)
    assert result.duration["index"] == pytest.approx(1.875 / 1.2, abs=2e-3)
    t = np.array([s.board_time for s in trace])
    sp = np.array([s.target[INDEX] for s in trace])
    T = result.duration["index"]
    # the path's start on the board's clock: the tick that fits best (samples every 2 ms)
    first = t[np.flatnonzero(sp > 5e-5)[0]]
    starts = np.arange(first - 0.1, first, 1e-3)
    misfit = [np.max(np.abs(sp - min_jerk_profile((t - t0) / T))) for t0 in starts]
    t0 = starts[int(np.argmin(misfit))]
    # on the curve to a few counts (the wire carries 1e-4 rad; a count is 1.9e-4)
    assert min(misfit) < 6e-4
    on_path = (t >= t0) & (t <= t0 + T + 0.01)
    speed = (sp[10:] - sp[:-10]) / (t[10:] - t[:-10])  # over 20 ms: the wire's 1e-4 rad
    assert np.max(speed) < 1.2 * 1.01  # the limit held
    err = np.array([s.theta2[INDEX] - s.target[INDEX] for s in trace])
    assert np.sqrt(np.mean(err[on_path] ** 2)) < math.radians(1.0)
    assert np.max(np.abs(err)) < math.radians(3.0)


def test_the_feedforward_keeps_the_finger_on_the_path(hand: Hand) -> None:
    def worst() -> float:
        hand.move({INDEX: 0.0}, 0.0)
        trace = record(hand)
        hand.move({INDEX: 1.2}, 1.5)
        return max(abs(s.theta2[INDEX] - s.target[INDEX]) for s in trace)

    hand.set_telemetry(500)
    with_ff = worst()
    hand.set_motion(INDEX, kv=0.0, ka=0.0)
    without = worst()
    assert with_ff < math.radians(3.0)
    assert without > 3 * with_ff


def test_a_move_waits_for_the_paths_then_settles(board: EmulatedBoard, hand: Hand) -> None:
    t0 = board.sim_time
    result = hand.move([0.6, 0.2, 0.5, 1.0, 0.0], 1.0)
    assert set(result.stretched) == {"ring"}  # 1 rad in 1 s: 1.875 rad/s at mid-path
    assert board.sim_time - t0 >= result.longest
    st = hand.state()
    np.testing.assert_allclose(st.theta2, [0.6, 0.2, 0.5, 1.0, 0.0], atol=math.radians(2.0))
    assert [f.mode for f in st] == [M.ControlMode.POSITION] * 5


def test_the_demo_poses_are_tracked_within_the_goal(hand: Hand) -> None:
    hand.set_telemetry(200)
    trace = record(hand)
    for name in DEFAULT_SEQUENCE:
        hand.pose(name)
        assert hand.last_move is not None and hand.last_move.stretched == ()
        hand.clock.sleep(0.3)
    for i, name in enumerate(hand.fingers):
        closed = [s.fingers[i].closed_loop for s in trace]
        got = tracking([s.theta2[i] for s in trace], [s.target[i] for s in trace], closed)
        assert got.samples > 1000
        assert got.within(math.radians(1.0), math.radians(3.0)), (name, got)
