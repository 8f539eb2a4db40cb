"""Telemetry to an append-safe CSV log (:class:`utrf.datalog.CsvLog`), one row per sample.

Columns, SI: ``host_time_s`` (Unix seconds on a real link, simulated seconds on a driven
emulated board), ``board_time_s`` (the board's clock, unwrapped), ``seq`` (the stream seq;
empty for a ``get_state`` reply), then per finger ``<name>_theta2_rad``, ``<name>_target_rad``,
``<name>_duty_a``, ``<name>_duty_b``, ``<name>_mode`` (the ControlMode name),
``<name>_faults`` (the FaultBits as an integer), ``<name>_tip_x_m``, ``<name>_tip_y_m``.
Every row is flushed as it is written: a run killed at any moment keeps every sample taken.
The bench runs read these files back with :func:`utrf.datalog.read_log`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path

from utrf.datalog import CsvLog
from utrf.hand.state import HandState

FINGER_FIELDS = (
    "theta2_rad",
    "target_rad",
    "duty_a",
    "duty_b",
    "mode",
    "faults",
    "tip_x_m",
    "tip_y_m",
)


def log_columns(finger_names: Sequence[str]) -> list[str]:
    cols = ["host_time_s", "board_time_s", "seq"]
    for name in finger_names:
        cols += [f"{name}_{field}" for field in FINGER_FIELDS]
    return cols


@functools.cache
def _line_format(fingers: int) -> str:
    """The ``%`` format of a row of ``fingers`` fingers, the fields as :meth:`TelemetryLog.row`
    formats them."""
    finger = "%.4f,%.4f,%.2f,%.2f,%s,%d,%.5f,%.5f"
    return ",".join(["%.6f", "%.6f", "%s", *[finger] * fingers]) + "\n"


class TelemetryLog:
    """Writes :class:`HandState` samples to ``path`` (appending when the columns match)."""

    def __init__(self, path: str | Path, finger_names: Sequence[str]) -> None:
        self.columns = log_columns(finger_names)
        self._log = CsvLog(path, self.columns)
        self.path = self._log.path

    @property
    def rows_written(self) -> int:
        return self._log.rows_written

    def write(self, state: HandState) -> None:
        self._log.write_line(self.line(state))

    @staticmethod
    def line(state: HandState) -> str:
        """``state``'s row as the log's text, formatted at once (every sample is logged):
        the CSV writer's text of :meth:`row` (a test compares them)."""
        values: list[object] = [
            state.host_time,
            state.board_time,
            "" if state.seq is None else state.seq,
        ]
        for f in state.fingers:
            values += [f.theta2, f.target, f.duty_a, f.duty_b, f.mode.name, int(f.faults),
                       f.tip_x, f.tip_y]  # fmt: skip
        return _line_format(len(state.fingers)) % tuple(values)

    @staticmethod
    def row(state: HandState) -> list[object]:
        """``state``'s row, field by field (the general form :meth:`line` formats at once)."""
        row: list[object] = [
            f"{state.host_time:.6f}",
            f"{state.board_time:.6f}",
            "" if state.seq is None else state.seq,
        ]
        for f in state.fingers:
            row += [
                f"{f.theta2:.4f}",
                f"{f.target:.4f}",
                f"{f.duty_a:.2f}",
                f"{f.duty_b:.2f}",
                f.mode.name,
                int(f.faults),
                f"{f.tip_x:.5f}",
                f"{f.tip_y:.5f}",
            ]
        return row

    def close(self) -> None:
        self._log.close()

    def __enter__(self) -> TelemetryLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
