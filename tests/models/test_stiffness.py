"""Deflection against payload at the straight horizontal pose (Sec. IV-A)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from utrf.models import statics, stiffness
from utrf.models.geometry import FingerGeometry
from utrf.models.statics import Load


def test_curve_is_the_statics_from_the_zero_payload_tip(geom: FingerGeometry) -> None:
    curve = stiffness.deflection_curve(geom, [1.0, 3.0], model="serial")
    zero = statics.solve(geom, 0.0, Load())
    for w, d, v in zip(curve.loads_kg, curve.deflection_m, curve.vertical_m, strict=True):
        loaded = statics.solve(geom, 0.0, Load(payload_kg=w))
        assert d == pytest.approx(np.hypot(*(loaded.tip_m - zero.tip_m)), rel=1e-9)
        assert v == pytest.approx(zero.tip_m[1] - loaded.tip_m[1], rel=1e-9)
    assert curve.secant_stiffness_n_per_m == pytest.approx(
        3.0 * statics.GRAVITY_MPS2 / curve.at(3.0)
    )


def test_fit_stiffness_through_the_origin(geom: FingerGeometry) -> None:
    curve = stiffness.deflection_curve(geom, stiffness.PAPER_LOADS_KG)
    k = curve.fit_stiffness_n_per_m
    # The least-squares slope minimises the force residual: perturbing it can only do worse.
    res = lambda kk: np.sum((curve.forces_n - kk * curve.deflection_m) ** 2)  # noqa: E731
    assert res(k) <= min(res(k * 1.001), res(k * 0.999))
    # Nearly linear: secant and slope within a few per cent.
    assert k == pytest.approx(curve.secant_stiffness_n_per_m, rel=0.05)


def test_serial_is_softer_than_printed_at_the_straight_pose(geom: FingerGeometry) -> None:
    s = stiffness.deflection_curve(geom, [3.0], model="serial")
    p = stiffness.deflection_curve(geom, [3.0], model="printed")
    # Serial adds the proximal stretches to every distal joint, so it sags more.
    assert s.at(3.0) > p.at(3.0)


def test_softer_tendons_sag_more(geom: FingerGeometry) -> None:
    from dataclasses import replace

    # Half the modulus, twice the sag: exactly so for small loads, less at large ones, where
    # the sag shortens the payload's moment arm.
    soft_geom = replace(geom, tendon_youngs_modulus_pa=100e9)
    small = [stiffness.deflection_curve(g, [0.05]).at(0.05) for g in (geom, soft_geom)]
    large = [stiffness.deflection_curve(g, [3.0]).at(3.0) for g in (geom, soft_geom)]
    assert small[1] == pytest.approx(2 * small[0], rel=0.005)
    assert large[0] < large[1] < 2 * large[0]


def test_bad_loads_are_refused(geom: FingerGeometry) -> None:
    with pytest.raises(statics.StaticsError, match="loads_kg"):
        stiffness.deflection_curve(geom, [0.0, 1.0])
    with pytest.raises(KeyError, match="not on the curve"):
        stiffness.deflection_curve(geom, [1.0]).at(2.0)


def test_figure_is_written(geom: FingerGeometry, tmp_path: Path) -> None:
    out = stiffness.plot(
        [stiffness.deflection_curve(geom, model=m) for m in statics.MODELS], tmp_path / "s.png"
    )
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
