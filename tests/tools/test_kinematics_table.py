"""The firmware's kinematics table: current, within its error bound, and what the header says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tools import kinematics_table as ft
from utrf.models import kinematics
from utrf.models.geometry import FingerGeometry, HandGeometry


@pytest.fixture(scope="module")
def built() -> tuple[list[ft.GeometryTable], list[int]]:
    return ft.build_tables(HandGeometry.default())


def test_committed_header_is_current(capsys: pytest.CaptureFixture[str]) -> None:
    assert ft.main(["--check"]) == 0, "run `python -m tools.kinematics_table` and commit the header"


def test_check_notices_a_stale_header(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stale = tmp_path / "k.h"
    stale.write_text(ft.DEFAULT_OUT.read_text().replace("{0, ", "{1, ", 1))
    assert ft.main(["--check", "--out", str(stale)]) == 1
    assert "stale" in capsys.readouterr().err


def test_interpolation_stays_within_the_bound_between_the_build_probes(built) -> None:
    tables, _ = built
    rng = np.random.default_rng(11)
    for t in tables:
        lo, hi = t.geometry.theta2_range_rad
        theta2 = rng.uniform(lo, hi, 200_000)  # not the generator's own probe grid
        q = kinematics.q_from_theta2(t.geometry, theta2)
        exact_tip = kinematics.tip_position(t.geometry, q)
        got = ft.interpolate(t, theta2)
        err = np.hypot(*(got[:, 3:5] - exact_tip).T)
        assert err.max() <= ft.DEFAULT_MAX_TIP_ERROR_M * 1.01
        assert np.abs(got[:, 0] - q).max() <= t.worst_q_error_m * 1.01 + 1e-9


def test_header_rows_are_the_tables(built) -> None:
    tables, finger_table = built
    text = ft.DEFAULT_OUT.read_text()
    for gi, t in enumerate(tables):
        body = re.search(
            rf"kRows{gi}\[(\d+)\]\[kColumns\] UTRF_PROGMEM = \{{(.*?)\n\}};", text, re.S
        )
        assert body is not None and int(body.group(1)) == t.rows
        rows = np.array(
            [[int(v) for v in r.split(",")] for r in re.findall(r"\{([-\d, ]+)\}", body.group(2))]
        )
        np.testing.assert_array_equal(rows, t.raw)
    assert f"kFingerGeometry[5] = {{{', '.join(map(str, finger_table))}}}" in text
    assert f"kTableBytes = {sum(t.nbytes for t in tables)}" in text


def test_a_table_needs_fewer_rows_for_a_looser_bound() -> None:
    g = FingerGeometry.default()
    assert ft.build_table(g, 2e-4).rows < ft.build_table(g, 5e-5).rows
