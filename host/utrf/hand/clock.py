"""The time a :class:`~utrf.hand.Hand` paces itself by.

On a real board (or an emulated one served in real time) that is the wall clock. On a driven
emulated board it is the board's simulated time, and sleeping runs the board
(:class:`~utrf.hand.simlink.SimLink`): the same trajectory code then runs as fast as the
machine allows and gives the same result on every run.
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Monotonic seconds (simulated seconds on a driven board)."""

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass (non-positive: return at once)."""

    def timestamp(self) -> float:
        """The host time written to logs: Unix seconds, or simulated seconds."""


class WallClock:
    """``time.monotonic``/``time.sleep``; logs get Unix time."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def timestamp(self) -> float:
        return time.time()
