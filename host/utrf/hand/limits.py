"""The Joint-2 limits the board holds, as the host knows them: what a move's or a pose's
targets are checked against before anything is sent."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from utrf.hand.errors import TargetError
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as m


class JointLimits:
    """(θ2 min, θ2 max) in rad a finger: the hand file's ranges until read from the board."""

    def __init__(self, geometry: HandGeometry, names: tuple[str, ...]) -> None:
        self.names = names
        self.theta2: list[tuple[float, float]] = [
            f.geometry.theta2_range_rad for f in geometry.fingers
        ]

    def take(self, lim: m.Limits) -> None:
        """A finger's limits as the board reports them (``get_limits``)."""
        self.theta2[lim.finger] = (lim.theta2_min, lim.theta2_max)

    def read(self, get: Callable[[int], m.Limits]) -> None:
        """Every finger's limits, one ``get(finger)`` each."""
        for i in range(len(self.names)):
            self.take(get(i))

    def describe(self, i: int) -> str:
        lo, hi = self.theta2[i]
        return f"[{lo:.3f}, {hi:.3f}] rad ([{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg)"

    def check(self, theta2: Mapping[int, float], during: str) -> None:
        """TargetError naming the first finger whose target lies beyond its limits."""
        for i, t in theta2.items():
            lo, hi = self.theta2[i]
            if not lo - 1e-4 <= t <= hi + 1e-4:
                raise TargetError(
                    f"{during}: finger {self.names[i]!r} target {t:.3f} rad "
                    f"({math.degrees(t):.1f} deg) is outside its Joint-2 limits "
                    f"{self.describe(i)}"
                )
