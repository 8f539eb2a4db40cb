"""The user-facing client of the UTRF-RoboHand: :class:`Hand` and what it reports.

See :mod:`utrf.hand.client` for the API and ``docs/hand.md`` for a guide.
"""

from utrf.hand.client import DEFAULT_TELEMETRY_HZ, DEFAULT_TOLERANCE, Hand, MoveResult
from utrf.hand.clock import Clock, WallClock
from utrf.hand.errors import (
    FingerFaultError,
    HandError,
    NotControlledError,
    NotSettledError,
    TargetError,
)
from utrf.hand.state import FaultEvent, FingerState, HandState, fault_names
from utrf.hand.telemetry_log import TelemetryLog, log_columns

__all__ = [
    "DEFAULT_TELEMETRY_HZ",
    "DEFAULT_TOLERANCE",
    "Clock",
    "FaultEvent",
    "FingerFaultError",
    "FingerState",
    "Hand",
    "HandError",
    "HandState",
    "MoveResult",
    "NotControlledError",
    "NotSettledError",
    "TargetError",
    "TelemetryLog",
    "WallClock",
    "fault_names",
    "log_columns",
]
