"""How closely each finger follows the setpoint its controller uses.

The state stream's ``target`` is the setpoint the board's controller uses at that tick (a
move's path point while it runs, else the target), so the tracking error of a sample is
``theta2 - target``. Only samples with the finger under closed-loop control (POSITION or
GRASP) count: an idle finger has no setpoint to follow.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from utrf.datalog import LogData

CLOSED_LOOP_MODES = ("POSITION", "GRASP")


@dataclass(frozen=True)
class Tracking:
    """One finger's tracking error over a run, rad."""

    rms: float
    worst: float
    samples: int

    def within(self, rms: float, worst: float) -> bool:
        return self.samples > 0 and self.rms <= rms and self.worst <= worst


def tracking(theta2: Sequence[float], target: Sequence[float], closed: Sequence[bool]) -> Tracking:
    """RMS and largest |theta2 - target| over the samples where ``closed`` is true."""
    th = np.asarray(theta2, dtype=float)
    tg = np.asarray(target, dtype=float)
    use = np.asarray(closed, dtype=bool)
    if not th.shape == tg.shape == use.shape:
        raise ValueError(
            f"theta2, target and closed must have one length, got {th.shape}, {tg.shape}, "
            f"{use.shape}"
        )
    e = (th - tg)[use]
    if e.size == 0:
        return Tracking(math.nan, math.nan, 0)
    return Tracking(float(np.sqrt(np.mean(e * e))), float(np.max(np.abs(e))), int(e.size))


def tracking_from_log(data: LogData, fingers: Iterable[str]) -> dict[str, Tracking]:
    """Per finger, from a telemetry log (``utrf.hand.telemetry_log`` columns)."""
    out: dict[str, Tracking] = {}
    for name in fingers:
        modes = data.column(f"{name}_mode")
        out[name] = tracking(
            [float(v) for v in data.column(f"{name}_theta2_rad")],
            [float(v) for v in data.column(f"{name}_target_rad")],
            [str(x) in CLOSED_LOOP_MODES for x in modes],
        )
    return out


def format_tracking(result: Mapping[str, Tracking]) -> str:
    """One line per finger, degrees (for people)."""
    lines = ["tracking (Joint 2 against the controller's setpoint, closed loop; deg):"]
    for name, t in result.items():
        lines.append(
            f"  {name:<7} RMS {math.degrees(t.rms):5.2f}  worst {math.degrees(t.worst):5.2f}"
            f"  ({t.samples} samples)"
        )
    return "\n".join(lines)
