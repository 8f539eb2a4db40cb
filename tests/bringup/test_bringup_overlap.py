"""Two fingers' steps at once (``utrf.bringup.overlap``), on a clock of its own: the waits
overlap, each wait ends when the clock has passed its end, and a failure in one stops the
other at its next wait, its clean-up run, before it is raised."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from utrf.bringup.overlap import SLICE_S, run_overlapped


class Clock:
    """A driven board's clock: time passes only in ``sleep``; it counts the slices asked."""

    def __init__(self) -> None:
        self.t = 0.0
        self.sleeps: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.t += seconds


def _hand() -> Any:  # a Hand's clock is all the overlap uses
    return SimpleNamespace(clock=Clock())


def test_two_fingers_waits_overlap_and_each_ends_on_the_clock() -> None:
    hand = _hand()
    ends: dict[str, float] = {}

    def job(name: str, seconds: float) -> str:
        for _ in range(4):
            hand.clock.sleep(seconds / 4)
        ends[name] = hand.clock.now()
        return name

    got = run_overlapped(hand, [lambda: job("a", 1.0), lambda: job("b", 0.6)], 2)
    assert got == ["a", "b"]
    assert ends["b"] == pytest.approx(0.6, abs=2 * SLICE_S)  # not after a's waits
    assert ends["a"] == pytest.approx(1.0, abs=2 * SLICE_S)  # the two at once, not 1.6 s
    assert max(hand.clock.sleeps) <= SLICE_S + 1e-12  # the other watched every slice
    assert "sleep" not in vars(hand.clock)  # the clock's own sleep again


def test_one_after_another_with_width_one() -> None:
    hand = _hand()

    def job() -> float:
        hand.clock.sleep(0.5)
        return hand.clock.now()

    assert run_overlapped(hand, [job, job], 1) == [0.5, 1.0]


def test_a_failure_stops_the_other_finger_after_its_clean_up() -> None:
    hand = _hand()
    cleaned: list[float] = []

    def fails() -> None:
        hand.clock.sleep(0.2)
        raise RuntimeError("the link is gone")

    def long() -> None:
        try:
            hand.clock.sleep(5.0)
        finally:
            cleaned.append(hand.clock.now())  # its pulse brakes it here

    with pytest.raises(RuntimeError, match="the link is gone"):
        run_overlapped(hand, [fails, long], 2)
    assert cleaned and cleaned[0] < 0.3  # stopped at its next wait, not after 5 s
    assert "sleep" not in vars(hand.clock)
