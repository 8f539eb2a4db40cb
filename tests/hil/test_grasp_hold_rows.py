"""The grasp hold's sample row formatted at once (``sample_line``, what the run writes) is the
CSV writer's text of the field-by-field row (``sample_row``), for any values."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from utrf.datalog import CsvLog
from utrf.hil.grasp_hold.config import sample_columns, sample_line, sample_row
from utrf.protocol import messages as m

NAMES = ["thumb", "index", "middle", "ring", "little"]
number = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def hand_states(draw: st.DrawFn) -> SimpleNamespace | None:
    if draw(st.booleans()):
        return None
    fingers = [
        SimpleNamespace(
            theta2=draw(number),
            target=draw(number),
            duty_a=draw(number),
            duty_b=draw(number),
            mode=draw(st.sampled_from(list(m.ControlMode))),
            faults=draw(st.integers(0, 255)),
        )
        for _ in NAMES
    ]
    return SimpleNamespace(fingers=fingers)


@settings(max_examples=200, deadline=None)
@given(
    t=number,
    phase=st.sampled_from(["baseline", "hold"]),
    position=st.lists(number, min_size=3, max_size=3),
    visible=st.booleans(),
    frame=st.integers(-1, 2**31),
    state=hand_states(),
    currents=st.lists(number, min_size=10, max_size=10),
)
def test_the_line_is_the_rows_text(
    tmp_path_factory, t, phase, position, visible, frame, state, currents
) -> None:
    sample = SimpleNamespace(position_m=np.array(position), visible=visible, frame=frame)
    cur = np.array(currents).reshape(5, 2)
    folder: Path = tmp_path_factory.mktemp("rows")
    with CsvLog(folder / "row.csv", sample_columns(NAMES)) as a:
        a.write(sample_row(t, phase, sample, state, cur))
    with CsvLog(folder / "line.csv", sample_columns(NAMES)) as b:
        b.write_line(sample_line(t, phase, sample, state, cur))
    assert (folder / "line.csv").read_bytes() == (folder / "row.csv").read_bytes()
