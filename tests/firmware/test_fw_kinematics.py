"""The firmware's coupled-kinematics lookup against the host's exact model."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import numpy as np
import pytest
from fwsim import BU, REPO

from tools import kinematics_table as firmware_table
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry


@pytest.fixture(scope="module")
def hand() -> HandGeometry:
    return HandGeometry.default()


@pytest.fixture(scope="module")
def tables(hand: HandGeometry) -> tuple[list[firmware_table.GeometryTable], list[int]]:
    return firmware_table.build_tables(hand)


def lookup(lib: ctypes.CDLL, g: int, theta2: float) -> tuple[bool, np.ndarray]:
    out = (ctypes.c_double * 6)()
    inside = bool(lib.fw_kin_lookup(g, theta2, out))
    return inside, np.array(out[:])


def test_generated_table_is_up_to_date() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "tools.kinematics_table", "--check"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr


def test_fingers_map_to_their_geometry(fwlib: ctypes.CDLL, hand: HandGeometry, tables) -> None:
    _, finger_table = tables
    assert [fwlib.fw_kin_geometry(f) for f in range(5)] == finger_table
    assert fwlib.fw_kin_geometry_count() == len(tables[0])
    assert fwlib.fw_kin_table_bytes() == sum(t.nbytes for t in tables[0])


def test_float_lookup_matches_the_exact_model(fwlib: ctypes.CDLL, tables) -> None:
    for g, table in enumerate(tables[0]):
        geom = table.geometry
        lo, hi = geom.theta2_range_rad
        theta2 = np.linspace(lo, hi, 3001)
        q = kinematics.q_from_theta2(geom, theta2)
        fk = kinematics.forward(geom, q)
        got = np.array([lookup(fwlib, g, float(t))[1] for t in theta2])
        tip_err = np.hypot(got[:, 4] - fk.tip[:, 0], got[:, 5] - fk.tip[:, 1]).max()
        # The generator's bound (interpolation + int16 quantisation), plus float32 rounding.
        assert tip_err <= table.worst_tip_error_m + 2e-6
        assert np.abs(got[:, 0] - q).max() <= table.worst_q_error_m + 1e-7
        assert np.abs(got[:, 1] - fk.theta[:, 0]).max() <= table.worst_angle_error_rad + 1e-5
        assert np.abs(got[:, 3] - fk.theta[:, 2]).max() <= table.worst_angle_error_rad + 1e-5
        assert np.allclose(got[:, 2], theta2, atol=1e-5)


def test_integer_tip_lookup_for_telemetry(fwlib: ctypes.CDLL, tables) -> None:
    """The tick-free integer path (1e-4 rad in, 1e-5 m out) stays within 0.07 mm."""
    fwlib.fw_kin_init()  # derives the integer constants (the firmware does it at start)
    x, y = ctypes.c_int16(), ctypes.c_int16()
    for g, table in enumerate(tables[0]):
        geom = table.geometry
        lo, hi = geom.theta2_range_rad
        worst = 0.0
        for au in range(int(np.ceil(lo * 1e4)), int(np.floor(hi * 1e4)), 7):
            fwlib.fw_kin_tip_raw(g, au, ctypes.byref(x), ctypes.byref(y))
            exact = kinematics.tip_position(geom, kinematics.q_from_theta2(geom, au * 1e-4))
            err = np.hypot(x.value * 1e-5 - exact[0], y.value * 1e-5 - exact[1])
            worst = max(worst, float(err))
        assert worst <= table.worst_tip_error_m + 2e-5


def test_lookup_clamps_outside_the_table(fwlib: ctypes.CDLL, tables) -> None:
    for g, table in enumerate(tables[0]):
        lo, hi = table.geometry.theta2_range_rad
        inside, at_lo = lookup(fwlib, g, lo)
        assert inside
        outside, below = lookup(fwlib, g, lo - 0.5)
        assert not outside
        assert np.allclose(below, at_lo)
        outside, above = lookup(fwlib, g, hi + 3.0)
        assert not outside
        assert np.allclose(above, lookup(fwlib, g, hi)[1])
        outside, _ = lookup(fwlib, g, float("nan"))
        assert not outside


def test_inverse_lookup_from_q_and_flexion(fwlib: ctypes.CDLL, tables) -> None:
    theta = ctypes.c_double()
    for g, table in enumerate(tables[0]):
        geom = table.geometry
        for t in np.linspace(*geom.theta2_range_rad, 41):
            q = float(kinematics.q_from_theta2(geom, t))
            assert fwlib.fw_kin_theta2_from_q(g, q, ctypes.byref(theta))
            assert theta.value == pytest.approx(t, abs=2e-4)
        assert not fwlib.fw_kin_theta2_from_q(g, geom.q_range_m[1] * 1.01, ctypes.byref(theta))
        q_full = fwlib.fw_kin_q_full(g)
        assert q_full == pytest.approx(float(kinematics.q_from_flexion(geom, 1.0)), abs=1e-6)


def test_angle_units(fwlib: ctypes.CDLL) -> None:
    """Internal angles (2 pi / 32768 rad) to the protocol's 1e-4 rad and back."""
    for rad in (-3.14159, -1.9635, -0.5, 0.0, 1e-3, 0.7, 1.9635, 3.14):
        b = fwlib.fw_bu(rad)
        assert abs(b * BU - rad) <= BU / 2 + 1e-9
        assert abs(fwlib.fw_au_from_bu(b) * 1e-4 - b * BU) <= 0.5e-4 + 1e-9
    # Angles stay within +-pi: any two differ by less than 2^15 units.
    assert fwlib.fw_bu(10.0) == 16383
    assert fwlib.fw_bu(-10.0) == -16384
