"""Calibration of data held at a Joint-2 angle (the firmware's boundary condition)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from utrf.models import calibration, statics
from utrf.models.calibration import CalibrationData, CalibrationError, Parameters
from utrf.models.geometry import HandGeometry

GEOM = HandGeometry.default().fingers[1].geometry
LOADS = np.repeat([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0], 3)


def test_hold_q_puts_the_loaded_joint_2_on_its_angle() -> None:
    theta2 = np.linspace(-0.3, 0.6, LOADS.size)
    q = calibration.hold_q(GEOM, theta2, LOADS)
    res = statics.solve_batch(GEOM, q, payload_kg=LOADS)
    np.testing.assert_allclose(res.theta[:, 1], theta2, atol=1e-11)
    # The controller pulls the stretch of Tendons 1 and 2 back in: q = R2 θ2 + e1 + e2.
    e = res.elongations_m
    np.testing.assert_allclose(q, GEOM.guide_radii_m[1] * theta2 + e[:, 0] + e[:, 1], atol=1e-11)


def test_theta2_data_fit_the_modulus_and_the_tracker_offset() -> None:
    truth = replace(GEOM, tendon_youngs_modulus_pa=150e9)
    rng = np.random.default_rng(3)
    theta2 = rng.normal(0.0, 0.004, LOADS.size)  # the hold's error, measured
    stub = CalibrationData(LOADS, np.zeros(LOADS.size), tip_m=np.zeros((LOADS.size, 2)),
                           theta2_rad=theta2)  # fmt: skip
    tip = calibration.predict(Parameters(truth, tip_offset_m=(4e-4, -7e-4)), stub, "serial")
    data = replace(stub, tip_m=tip + rng.normal(0, 1e-4, tip.shape))
    res = calibration.fit(data, GEOM)
    assert res.fitted == ("modulus", "tip_offset")
    sd = res.std_errors["modulus"]
    assert isinstance(sd, float) and sd < 0.1 * 150e9
    assert abs(res.params.geometry.tendon_youngs_modulus_pa - 150e9) < 4 * sd
    assert res.mean_error_m < 2.5e-4 < res.initial_errors_m.mean()
    with pytest.raises(CalibrationError, match="q_offset needs"):
        calibration.fit(data, GEOM, fit_params=["modulus", "q_offset"])


def test_csv_carries_the_held_angle(tmp_path: Path) -> None:
    data = CalibrationData(np.array([0.0, 1.0]), np.zeros(2), tip_m=np.array([[0.17, 0.0],
                           [0.1699, 0.002]]), theta2_rad=np.array([0.001, -0.002]))  # fmt: skip
    back = calibration.read_csv(calibration.write_csv(data, tmp_path / "d.csv"))
    assert back.hold == "theta2"
    np.testing.assert_allclose(back.theta2_rad, [0.001, -0.002])
    deg = tmp_path / "deg.csv"
    deg.write_text("load_kg,theta2_deg,deflection_mm\n1.0,1.0,2.0\n")
    assert calibration.read_csv(deg).theta2_rad == pytest.approx([np.pi / 180])
    both = tmp_path / "both.csv"
    both.write_text("load_kg,q_m,theta2_rad,deflection_m\n1.0,0,0,0.002\n")
    with pytest.raises(CalibrationError, match="not both"):
        calibration.read_csv(both)
