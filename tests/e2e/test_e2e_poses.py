"""Every pose of the library, on the real firmware and the plant, in simulated time: the
fingers reach the pose's targets (in the firmware's telemetry and in the plant itself) within
a bounded time; a grasp closes on an object and holds it with its effort, without a fault."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import DEFAULT_TOLERANCE, Hand
from utrf.poses import PoseLibrary
from utrf.protocol import messages as M

LIBRARY = PoseLibrary.load(include_user=False)
MOVE_S = 0.6
BOUND_S = MOVE_S + 2.5  # the move, then settling: the whole pose within this, simulated


@pytest.fixture(scope="module")
def shared(firmware_elf: Path) -> Iterator[tuple[EmulatedBoard, Hand]]:
    # One board for the poses: each starts from where the last one left the hand, which is
    # what a user does; the assertions do not depend on the start.
    with EmulatedBoard(firmware_elf, realtime=False, seed=3) as board, Hand.emulated(board) as hand:
        yield board, hand


@pytest.mark.parametrize("name", list(LIBRARY))
def test_pose_reaches_its_targets(shared: tuple[EmulatedBoard, Hand], name: str) -> None:
    board, hand = shared
    pose = LIBRARY[name]
    goal = pose.theta2(hand.geometry)
    start = hand.state().target
    t0 = board.sim_time
    hand.pose(name, duration=MOVE_S, timeout=BOUND_S - MOVE_S)
    took = board.sim_time - t0
    assert took < BOUND_S
    st = hand.state()
    if pose.grasp is None:
        assert [f.mode for f in st] == [M.ControlMode.POSITION] * 5
    else:  # the fingers that closed grasp; those that opened or stayed hold position
        assert {f.mode for f in st} <= {M.ControlMode.GRASP, M.ControlMode.POSITION}
        assert [f.mode == M.ControlMode.GRASP for f in st] == list(goal > start + DEFAULT_TOLERANCE)
    assert not any(f.faults for f in st)
    np.testing.assert_allclose(st.target, goal, atol=2e-4)  # the board took the targets
    # Nothing in the way: every finger is there, as the firmware measures it and in the plant.
    # (read just after settling: within the tolerance, give or take an ADC count, 7.7 mrad)
    np.testing.assert_allclose(st.theta2, goal, atol=DEFAULT_TOLERANCE + 0.008)
    np.testing.assert_allclose(board.theta2, goal, atol=DEFAULT_TOLERANCE + 0.01)
    # ...and the whole finger follows the coupling theta_i = q / R_i
    for i, f in enumerate(hand.geometry.fingers):
        r = np.asarray(f.geometry.guide_radii_m)
        np.testing.assert_allclose(board.theta[i], board.theta2[i] * r[1] / r, atol=1e-3)


def test_grasp_closes_on_an_object_and_holds_it_with_its_effort(
    board: EmulatedBoard, hand: Hand
) -> None:
    hand.pose("open", duration=0.3)
    pose = LIBRARY["grasp-bottle"]
    goal = pose.theta2(hand.geometry)
    # The bottle stops index, middle and ring at 60 % of their way.
    contact = {i: 0.6 * goal[i] for i in (1, 2, 3)}
    for i, angle in contact.items():
        board.block_finger(i, angle, direction="flexion")
    t0 = board.sim_time
    hand.pose("grasp-bottle", duration=MOVE_S, timeout=3.0)
    assert board.sim_time - t0 < MOVE_S + 3.0
    hand.clock.sleep(1.0)  # holding: longer than the stall time, no fault
    st = hand.state()
    assert [f.mode for f in st] == [M.ControlMode.GRASP] * 5  # all five closed
    assert not any(f.faults for f in st), [str(f.faults) for f in st]
    for i, angle in contact.items():
        assert board.theta2[i] == pytest.approx(angle, abs=0.02)  # at the object
        # pressing on it, within the effort: flexor duty at most the effort
        assert 0 < st[i].duty_a <= pose.grasp.effort + 0.01
    for i in (0, 4):  # free fingers close fully
        assert st[i].theta2 == pytest.approx(goal[i], abs=DEFAULT_TOLERANCE)
    assert math.isfinite(board.tendon_tension.sum())
