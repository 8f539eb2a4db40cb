"""The demo's tracking goal checked on a hand (``utrf.bringup.demo_goal``): met by the model
build on its default gains, not met when a finger cannot follow."""

from __future__ import annotations

import math

import pytest
from bringup_helpers import Built

from utrf.bringup.demo_goal import GOAL_RMS_RAD, demo_goal


@pytest.mark.slow
def test_the_model_build_meets_the_demo_goal(built: Built) -> None:
    with built() as (board, hand):
        goal = demo_goal(hand)
        board.run_for(0.05)  # the brake command's tick
        assert all(mode in ("coast", "brake") for a, b in board.drive for mode in (a[0], b[0]))
    assert goal.ok, goal.line()
    assert len(goal.settled) == 5 and all(t.samples > 500 for t in goal.tracking.values())
    assert max(t.rms for t in goal.tracking.values()) <= GOAL_RMS_RAD
    assert "goal met" in goal.line()


@pytest.mark.slow
def test_a_finger_that_cannot_follow_fails_the_goal(built: Built) -> None:
    with built("unpowered:1") as (_, hand):
        goal = demo_goal(hand, sequence=("open", "fist"))
    assert not goal.ok
    assert not all(goal.settled.values()) or goal.tracking["index"].worst > math.radians(3)
