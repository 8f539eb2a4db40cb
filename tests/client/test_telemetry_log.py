"""The telemetry log's row, formatted at once (``TelemetryLog.line``, every sample's fast
path) against the CSV writer's text of the same row field by field (``TelemetryLog.row``)."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from utrf.datalog import read_log
from utrf.hand.state import FingerState, HandState
from utrf.hand.telemetry_log import TelemetryLog
from utrf.protocol import messages as m

NAMES = ("thumb", "index", "middle", "ring", "little")
# angles, duties and times as they come, and the odd ones a float format treats on its own
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-4.0, max_value=4.0),
    st.sampled_from([0.0, -0.0, 1e-9, -1e-9, 0.00005, -0.00005, 0.125, 2.5e-5]),
)
fingers = st.tuples(numbers, numbers, numbers, numbers, st.sampled_from(list(m.ControlMode)),
                    st.integers(0, 255), numbers, numbers)  # fmt: skip


def _state(host: float, board: float, seq: int | None, fs: list[tuple]) -> HandState:
    return HandState(
        board_time=board,
        host_time=host,
        seq=seq,
        fingers=tuple(
            FingerState(NAMES[i], i, f[0], f[1], f[2], f[3], f[4], m.FaultBits(f[5]), f[6], f[7])
            for i, f in enumerate(fs)
        ),
    )


@settings(max_examples=300, deadline=None)
@given(numbers, numbers, st.one_of(st.none(), st.integers(0, 2**32)),
       st.lists(fingers, min_size=5, max_size=5))  # fmt: skip
def test_the_formatted_line_is_the_csv_writers_row(
    host: float, board: float, seq: int | None, fs: list[tuple]
) -> None:
    state = _state(host, board, seq, fs)
    text = io.StringIO()  # the formatting alone, no file
    csv.writer(text, lineterminator="\n").writerow(TelemetryLog.row(state))
    assert TelemetryLog.line(state) == text.getvalue()


def test_a_logged_sample_reads_back(tmp_path: Path) -> None:
    state = _state(
        12.5, 0.25, 7, [(0.5, 0.6, 0.25, -0.5, m.ControlMode.POSITION, 4, 0.1, 0.02)] * 5
    )
    with TelemetryLog(tmp_path / "t.csv", NAMES) as log:
        log.write(state)
        log.write(_state(math.nan, 0.26, None, [(0.5, 0.6, 0.25, -0.5, m.ControlMode.GRASP,
                                                  0, 0.1, 0.02)] * 5))  # fmt: skip
        assert log.rows_written == 2
    rows = read_log(tmp_path / "t.csv", log.columns).rows
    assert rows[0]["seq"] == 7 and rows[0]["index_mode"] == "POSITION"
    assert rows[0]["ring_faults"] == 4 and rows[0]["little_duty_b"] == -0.5
    assert rows[1]["seq"] == "" and math.isnan(rows[1]["host_time_s"])


def test_a_line_of_the_wrong_width_is_refused(tmp_path: Path) -> None:
    with TelemetryLog(tmp_path / "t.csv", NAMES) as log:
        with pytest.raises(ValueError, match="a line of 43 fields"):
            log._log.write_line("1,2,3\n")
        assert log.rows_written == 0
