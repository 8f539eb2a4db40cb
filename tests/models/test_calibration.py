"""Calibration: recover known parameters from synthetic data; report errors like the paper."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from utrf.models import calibration, statics
from utrf.models.calibration import CalibrationError, Parameters
from utrf.models.geometry import FingerGeometry

LOADS = np.repeat([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0], 3)  # the paper's protocol, 3 repeats


def _truth(geom: FingerGeometry) -> Parameters:
    return Parameters(replace(geom, tendon_youngs_modulus_pa=120e9), q_offset_m=4e-4)


def test_fit_recovers_modulus_and_offset_from_noisy_positions(geom: FingerGeometry) -> None:
    data = calibration.synthesize(_truth(geom), LOADS, noise_m=1e-4, seed=2)
    res = calibration.fit(data, geom)
    e, sd = res.params.geometry.tendon_youngs_modulus_pa, res.std_errors["modulus"]
    assert isinstance(sd, float) and abs(e - 120e9) < 4 * sd and sd < 0.02 * 120e9
    sq = res.std_errors["q_offset"]
    assert isinstance(sq, float) and abs(res.params.q_offset_m - 4e-4) < 4 * sq
    # The reported errors are the per-row tip distances, recomputed here from the statics.
    q = data.q_m + res.params.q_offset_m
    pred = statics.solve_batch(res.params.geometry, q, payload_kg=data.load_kg).tip
    dist = np.hypot(*(pred - data.tip_m).T)
    out = res.to_json()
    assert out["mean_error_m"] == pytest.approx(dist.mean())
    assert out["max_error_m"] == pytest.approx(dist.max())
    assert out["mean_error_pct"] == pytest.approx(100 * dist.mean() / 0.17)
    # Fitting explains the data to about the noise (2D Gaussian: mean distance ~1.25 sigma).
    assert dist.mean() < 2e-4 < res.initial_errors_m.mean()


def test_noise_free_data_fit_exactly(geom: FingerGeometry) -> None:
    truth = Parameters(replace(geom, tendon_youngs_modulus_pa=150e9), tip_offset_m=(1e-3, -2e-3))
    data = calibration.synthesize(truth, LOADS, q_m=0.002)
    res = calibration.fit(data, geom, fit_params=["modulus", "tip_offset"])
    assert res.max_error_m < 1e-9
    assert res.params.geometry.tendon_youngs_modulus_pa == pytest.approx(150e9, rel=1e-6)
    np.testing.assert_allclose(res.params.tip_offset_m, (1e-3, -2e-3), atol=1e-9)


def test_deflection_data_fit_the_modulus(geom: FingerGeometry) -> None:
    truth = Parameters(replace(geom, tendon_youngs_modulus_pa=160e9))
    data = calibration.synthesize(truth, LOADS[3:], kind="deflection", noise_m=5e-5, seed=4)
    res = calibration.fit(data, geom)
    assert res.fitted == ("modulus",)
    assert res.params.geometry.tendon_youngs_modulus_pa == pytest.approx(160e9, rel=0.01)
    with pytest.raises(CalibrationError, match="need tip positions"):
        calibration.fit(data, geom, fit_params=["modulus", "q_offset"])


def test_inseparable_parameters_are_flagged(geom: FingerGeometry) -> None:
    # At one pose the deflection scales roughly as 1 / (E R²): modulus and radius scale
    # separate only through the nonlinearity, barely.
    data = calibration.synthesize(Parameters(geom), LOADS[3:], kind="deflection")
    res = calibration.fit(data, geom, fit_params=["modulus", "radius_scale"])
    assert any("barely separate" in w for w in res.warnings) or res.condition_number > 1e3
    # Rows at one pose and one load cannot tell a q offset from a tracker shift at all.
    same = calibration.synthesize(Parameters(geom), [1.0] * 4, q_m=0.003, noise_m=1e-5)
    res = calibration.fit(same, geom, fit_params=["q_offset", "tip_offset"])
    assert any("barely separate ['q_offset', 'tip_offset']" in w for w in res.warnings)
    assert res.std_errors == {"q_offset": None, "tip_offset": None}


def test_csv_round_trip_and_units(geom: FingerGeometry, tmp_path: Path) -> None:
    data = calibration.synthesize(_truth(geom), LOADS[:6], noise_m=1e-5)
    path = calibration.write_csv(data, tmp_path / "d.csv", comment="synthetic\nfor a test")
    back = calibration.read_csv(path)
    np.testing.assert_allclose(back.tip_m, data.tip_m, rtol=1e-8)
    np.testing.assert_allclose(back.load_kg, data.load_kg)
    mm = tmp_path / "mm.csv"
    mm.write_text("load_kg,deflection_mm\n0.5,5.0\n1.0,10.0\n")
    d = calibration.read_csv(mm)
    assert d.kind == "deflection" and d.deflection_m.tolist() == [0.005, 0.01]
    assert d.q_m.tolist() == [0.0, 0.0]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("tip_x_m,tip_y_m\n0.1,0.0\n", "needs a load_kg column"),
        ("load_kg,tip_x_m\n1,0.1\n", "needs tip_x_m and tip_y_m, or deflection_m"),
        ("load_kg,deflection_m\n1,abc\n", r":2 deflection_m: not a number"),
        ("load_kg,deflection_m\n-1,0.01\n", "load_kg: must be >= 0"),
        ("load_kg,deflection_m\n1,0.01,3\n", "3 values for 2 columns"),
        ("load_kg,deflection_m\n", "no data rows"),
        ("# only a comment\n", "no header row"),
    ],
)
def test_bad_csv_names_line_and_column(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(CalibrationError, match=match):
        calibration.read_csv(p)


def test_bad_requests_are_named(geom: FingerGeometry, tmp_path: Path) -> None:
    data = calibration.synthesize(Parameters(geom), [1.0, 2.0])
    with pytest.raises(CalibrationError, match="unknown parameter 'stiffness'"):
        calibration.fit(data, geom, fit_params=["stiffness"])
    with pytest.raises(CalibrationError, match="listed twice"):
        calibration.fit(data, geom, fit_params=["modulus", "modulus"])
    with pytest.raises(CalibrationError, match="cannot fit"):
        one = calibration.synthesize(Parameters(geom), [1.0], kind="deflection")
        calibration.fit(one, geom, fit_params=["modulus", "radius_scale"])
    with pytest.raises(CalibrationError, match="no such file"):
        calibration.read_csv(tmp_path / "absent.csv")


def test_paper_point_gives_an_effective_modulus(geom: FingerGeometry) -> None:
    """The committed paper figure (24.386 mm at 3 kg) fits a modulus that reproduces it."""
    from importlib import resources

    ref = resources.files("utrf") / "data" / "calibration" / "paper_3kg.csv"
    with resources.as_file(ref) as path:
        data = calibration.read_csv(path)
    res = calibration.fit(data, geom)
    assert res.max_error_m < 1e-7
    from utrf.models import stiffness

    fitted = stiffness.deflection_curve(res.params.geometry, [3.0]).at(3.0)
    assert fitted == pytest.approx(stiffness.PAPER_DEFLECTION_M, rel=1e-5)
