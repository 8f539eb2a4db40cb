"""Campaign builds that were named wrong, each finger brought up alone on its seeded build
(``BuildFaults.random(seed, 3)``, the build ``make bringup-campaign`` draws): what it is named
now (docs/bringup.md, the campaign's table)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from utrf.bringup import bringup
from utrf.emulator import BuildFaults, EmulatedBoard
from utrf.hand import Hand


def _named(firmware_elf: Path, seed: int, finger: int, upto: str) -> list[str]:
    build = BuildFaults.random(seed, 3)
    board = EmulatedBoard(firmware_elf, realtime=False, seed=seed, build=build)
    with board, Hand.emulated(board) as hand:
        result = bringup(hand, fingers=[finger], upto=upto)
    return [f.kind for f in result.findings]


@pytest.fixture
def named(firmware_elf: Path, make: Callable[..., None]) -> Callable[[int, int, str], list[str]]:
    make("emulator")
    return lambda seed, finger, upto: _named(firmware_elf, seed, finger, upto)


def test_a_take_up_run_far_open_is_a_lead_swapped(
    named: Callable[[int, int, str], list[str]],
) -> None:
    """Seed 15's index (``swap-lead-a``): held by the pretension and moved both ways by the
    pulses, as a finger wired right, but its take-up ran it 0.73 rad open (motor A pushing);
    it was taken as wired right and its closing search stuck at once (named friction)."""
    assert named(15, 1, "wiring") == ["lead-a-swapped"]


@pytest.mark.slow
def test_a_weak_thumb_is_named_weak_from_three_steps_each_way(
    named: Callable[[int, int, str], list[str]],
) -> None:
    """Seed 30's thumb (``weak-motor`` 0.29): one step from rest each way read 0.8 and 1.4
    times the model's lag (named friction); the medians of three read it late both ways."""
    assert named(30, 0, "plant") == ["weak-motor"]


@pytest.mark.slow
def test_a_slack_thumb_late_like_a_weak_motor_is_slack(
    named: Callable[[int, int, str], list[str]],
) -> None:
    """Seed 47's thumb (``slack``): late both ways from rest as a weak motor is (2.6 and 9.1
    times the model's lag), named weak-motor and saved as brought up; its reversals wait
    for the strand beyond its lag (0.108 s, alone)."""
    assert named(47, 0, "plant") == ["slack"]


@pytest.mark.slow
def test_friction_stuck_short_of_the_stop_is_not_a_narrow_range(
    named: Callable[[int, int, str], list[str]],
) -> None:
    """Seed 10's thumb (10 N of friction): its closing search paused at 1.35 rad, went on
    and stuck again at 1.83 of the joint's 3.31, which was named a narrow range as well;
    a frictional finger's stick after a pause is not the build's stop."""
    assert named(10, 0, "plant") == ["friction"]
