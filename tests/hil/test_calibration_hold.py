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


def _held_data(rng: np.random.Generator, theta_sd: float, tracker_sd: float):
    """Joint-2-held rows whose measured angle is off by N(0, theta_sd) and whose tip is seen
    with N(0, tracker_sd) per axis; with each row's tip covariance, as a rig run gives it."""
    truth = replace(GEOM, tendon_youngs_modulus_pa=150e9)
    theta2 = np.zeros(LOADS.size)
    true_theta2 = theta2 + rng.normal(0.0, theta_sd, LOADS.size)
    stub = CalibrationData(LOADS, np.zeros(LOADS.size), tip_m=np.zeros((LOADS.size, 2)),
                           theta2_rad=true_theta2)  # fmt: skip
    tip = calibration.predict(Parameters(truth), stub, "serial")
    tip = tip + rng.normal(0.0, tracker_sd, tip.shape)
    # d tip / d theta2 of the held finger, to carry the angle's error onto the tip
    h = 1e-5
    jac = (
        calibration.predict(Parameters(GEOM), replace(stub, theta2_rad=theta2 + h), "serial")
        - calibration.predict(Parameters(GEOM), replace(stub, theta2_rad=theta2 - h), "serial")
    ) / (2 * h)
    cov = tracker_sd**2 * np.eye(2) + theta_sd**2 * np.einsum("ni,nj->nij", jac, jac)
    return replace(stub, theta2_rad=theta2, tip_m=tip, tip_cov_m2=cov)


@pytest.mark.slow
def test_row_covariances_weigh_the_fit_and_state_its_error() -> None:
    """Rows whose held angle is read with an error (0.3 mrad: about 0.1 mm at the tip, along
    the tip's Jacobian) and a tracker of 0.02 mm: over 30 draws, the weighted fit's stated
    error matches its scatter; unweighted, the residuals' scatter understates it (by about
    sqrt(2): the angle's error shows in y only, the x residuals carry the tracker's noise)."""
    rng = np.random.default_rng(5)
    z_w, z_u = [], []
    for _ in range(30):
        data = _held_data(rng, theta_sd=3e-4, tracker_sd=2e-5)
        w = calibration.fit(data, GEOM)
        assert w.chi2_per_dof is not None and w.chi2_per_dof < 3
        u = calibration.fit(replace(data, tip_cov_m2=None), GEOM)
        assert u.chi2_per_dof is None
        for res, z in ((w, z_w), (u, z_u)):
            sd = res.std_errors["modulus"]
            assert isinstance(sd, float)
            z.append((res.params.geometry.tendon_youngs_modulus_pa - 150e9) / sd)
    assert 0.7 < np.sqrt(np.mean(np.square(z_w))) < 1.3
    assert np.sqrt(np.mean(np.square(z_u))) > 1.25
    assert w.to_json()["chi2_per_dof"] == w.chi2_per_dof


def test_bad_row_covariances_are_named() -> None:
    data = _held_data(np.random.default_rng(1), theta_sd=3e-4, tracker_sd=2e-5)
    assert data.tip_cov_m2 is not None
    with pytest.raises(CalibrationError, match=r"shape \(21, 2, 2\)"):
        calibration.fit(replace(data, tip_cov_m2=data.tip_cov_m2[:3]), GEOM)
    singular = data.tip_cov_m2.copy()
    singular[4] = 0.0
    with pytest.raises(CalibrationError, match="row 4: not positive definite"):
        calibration.fit(replace(data, tip_cov_m2=singular), GEOM)
    skew = data.tip_cov_m2.copy()
    skew[2, 0, 1] += 1e-9
    with pytest.raises(CalibrationError, match="row 2: not a finite symmetric"):
        calibration.fit(replace(data, tip_cov_m2=skew), GEOM)
    defl = CalibrationData(LOADS, np.zeros(LOADS.size), deflection_m=np.zeros(LOADS.size),
                           tip_cov_m2=data.tip_cov_m2)  # fmt: skip
    with pytest.raises(CalibrationError, match="not with deflections"):
        calibration.fit(defl, GEOM)
