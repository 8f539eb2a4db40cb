"""The Joint-2 targets the host commanded last, finger by finger: what a wait settles on."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from utrf.protocol import messages as m


class Goals:
    """One target (rad) a finger, NaN where the host commanded none (or the finger left
    closed loop, or the board reset): then the board's own target counts."""

    def __init__(self) -> None:
        self.theta2 = np.full(m.FINGER_COUNT, np.nan)

    def set(self, idx: Sequence[int], theta2: Iterable[float]) -> None:
        self.theta2[list(idx)] = list(theta2)

    def forget(self, idx: Sequence[int] | None = None) -> None:
        """No target for these fingers (None: for any)."""
        if idx is None:
            self.theta2[:] = np.nan
        else:
            self.theta2[list(idx)] = np.nan

    def named(self) -> list[int]:
        """The fingers with a target."""
        return [i for i, t in enumerate(self.theta2) if np.isfinite(t)]
