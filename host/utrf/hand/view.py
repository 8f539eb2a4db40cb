"""The hand's state for people: a rich table (terminals) or one text line (logs, CI).

Angles in degrees, fingertips in mm, duties in percent, and they say so; the API, the JSON
output and the logs stay SI.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np
from rich.table import Table
from rich.text import Text

from utrf.hand.state import HandState, fault_names

UNITS_NOTE = "Joint-2 angles in degrees; A/B: motor duties in %; tip x, y in mm (API and logs: SI)"


def _deg(rad: float) -> str:
    return f"{math.degrees(rad):.1f}"


def state_table(
    state: HandState | None,
    *,
    title: str = "UTRF-RoboHand",
    goal: Sequence[float] | np.ndarray | None = None,
    tolerance: float | None = None,
    footer: str = "",
) -> Table:
    """One row per finger. ``goal``: the host's targets (rad) when they differ from the
    board's (during a trajectory); ``tolerance`` colours the error."""
    table = Table(title=title, caption=(footer + "\n" if footer else "") + UNITS_NOTE)
    columns: tuple[tuple[str, Literal["left", "right"]], ...] = (
        ("finger", "left"),
        ("mode", "left"),
        ("θ2 °", "right"),
        ("goal °", "right"),
        ("err °", "right"),
        ("A/B %", "right"),
        ("tip mm", "right"),
        ("faults", "left"),
    )
    for name, justify in columns:
        table.add_column(name, justify=justify, no_wrap=True)
    if state is None:
        table.add_row("(waiting)", *[""] * 7)
        return table
    for i, f in enumerate(state.fingers):
        target = goal[i] if goal is not None and math.isfinite(goal[i]) else f.target
        err = target - f.theta2
        style = ""
        if tolerance is not None:
            style = "green" if abs(err) <= tolerance else "yellow"
        table.add_row(
            f.name,
            f.mode.name,
            _deg(f.theta2),
            _deg(target) if f.closed_loop else "-",  # a target means nothing out of closed loop
            Text(_deg(err), style=style) if f.closed_loop else "-",
            f"{100 * f.duty_a:.0f}/{100 * f.duty_b:.0f}",
            f"{1e3 * f.tip_x:.0f}, {1e3 * f.tip_y:.0f}",
            Text(fault_names(f.faults), style="bold red" if f.faults else "dim"),
        )
    return table


def state_line(state: HandState) -> str:
    """``t=1.234s thumb 12.3/15.0° POSITION | index ...`` (measured/target in degrees)."""
    parts = []
    for f in state.fingers:
        fault = f" {fault_names(f.faults)}" if f.faults else ""
        parts.append(
            f"{f.name} {math.degrees(f.theta2):.1f}/{math.degrees(f.target):.1f}° "
            f"{f.mode.name}{fault}"
        )
    return f"t={state.board_time:.3f}s  " + " | ".join(parts)
