"""The :class:`~utrf.hand.Hand`'s own errors (the protocol's are in ``utrf.protocol.errors``).

Each names the finger and says how far off or what is wrong, in SI and, for people, degrees.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from utrf.hand.state import fault_names


class HandError(Exception):
    """Base class of the Hand's errors."""


class TargetError(HandError, ValueError):
    """A target the hand cannot take (unknown finger, wrong kind, outside the limits)."""


class NotSettledError(HandError, TimeoutError):
    """The fingers did not reach their targets in time.

    ``errors``: target − measured (rad) of each finger that was still off, by name.
    """

    def __init__(self, errors: Mapping[str, float], tolerance: float, timeout: float) -> None:
        self.errors = dict(errors)
        self.tolerance = tolerance
        self.timeout = timeout
        worst = sorted(self.errors.items(), key=lambda kv: -abs(kv[1]))
        parts = [
            f"{name} is {abs(err):.3f} rad ({math.degrees(abs(err)):.1f} deg) "
            f"{'short of' if err > 0 else 'past'} its target"
            for name, err in worst
        ]
        super().__init__(
            f"not settled within {timeout:g} s (tolerance {tolerance:.3f} rad = "
            f"{math.degrees(tolerance):.1f} deg): " + "; ".join(parts)
        )


class FingerFaultError(HandError):
    """A finger has latched faults (its motors are off, or it holds in its safe action)."""

    def __init__(self, faults: Mapping[str, int], during: str) -> None:
        self.faults = dict(faults)
        parts = [f"{name}: {fault_names(bits)}" for name, bits in self.faults.items()]
        super().__init__(
            f"{during}: latched fault(s) on " + "; ".join(parts) + ". Remove the cause, then "
            "hand.clear_faults() and command the finger again"
        )


class NotControlledError(HandError):
    """A finger the call waits for is not under closed-loop control (e.g. coasting)."""

    def __init__(self, modes: Mapping[str, str], during: str) -> None:
        self.modes = dict(modes)
        parts = [f"{name} is in {mode}" for name, mode in self.modes.items()]
        super().__init__(f"{during}: " + "; ".join(parts) + ", not POSITION or GRASP")
