"""The models vectorised over designs (utrf.models.design_batch) against their one-geometry
twins: tendons, statics_batch, statics_result's checks and workspace's raster areas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from utrf.campaign import design
from utrf.models import design_batch as db
from utrf.models import statics, tendons, workspace
from utrf.models.geometry import FingerGeometry, GeometryError


def random_geometries(n: int, seed: int) -> list[FingerGeometry]:
    rng = np.random.default_rng(seed)
    out: list[FingerGeometry] = []
    while len(out) < n:
        L = rng.uniform(0.03, 0.09, 3)
        R = rng.uniform(0.005, 0.016, 3)
        try:
            out.append(
                FingerGeometry(
                    link_lengths_m=tuple(L), guide_radii_m=tuple(R),
                    tendon_diameter_m=float(rng.uniform(0.0006, 0.0014)),
                    link_masses_kg=tuple(L * 0.16),
                    theta1_range_rad=(-math.radians(80), math.radians(80)),
                )
            )  # fmt: skip
        except GeometryError:
            continue
    return out


def designs_of(gs: list[FingerGeometry]) -> db.Designs:
    return db.Designs(
        link_lengths_m=np.array([g.link_lengths_m for g in gs]),
        guide_radii_m=np.array([g.guide_radii_m for g in gs]),
        tendon_diameter_m=np.array([g.tendon_diameter_m for g in gs]),
        tendon_youngs_modulus_pa=np.array([g.tendon_youngs_modulus_pa for g in gs]),
        actuating_tendon_length_m=np.array([g.actuating_tendon_length_m for g in gs]),
        link_masses_kg=np.array([g.link_masses_kg for g in gs]),
        theta1_max_rad=np.array([g.theta1_range_rad[1] for g in gs]),
    )


def test_tendons_and_coupling_match_the_one_geometry_model() -> None:
    gs = random_geometries(12, 1)
    d = designs_of(gs)
    wraps = db.straight_wraps(d)
    for i, g in enumerate(gs):
        assert wraps[i] == pytest.approx(tendons.straight_wrap_angles(g), rel=1e-12)
        assert 1 / db.compliances(d, wraps)[i] == pytest.approx(tendons.stiffnesses(g), rel=1e-12)
        assert db.coupling_q_max(d, wraps)[i] == pytest.approx(tendons.coupling_q_range_m(g)[1])


def test_equilibria_match_statics_batch_design_by_design() -> None:
    gs = random_geometries(8, 2)
    d = designs_of(gs)
    wraps = db.straight_wraps(d)
    payload, flexion = 0.8, 0.6
    q = np.array([flexion * g.q_range_m[1] for g in gs])
    got = db.equilibrium(d, q, np.full(d.n, payload), db.compliances(d, wraps))
    for i, g in enumerate(gs):
        ref = statics.solve_batch(g, q[i], payload_kg=payload, relaxation="none")
        assert got.converged[i] == ref.converged[0]
        assert got.tip[i] == pytest.approx(ref.tip[0], abs=1e-8)
        assert got.net_tensions_n[i] == pytest.approx(ref.net_tensions_n[0], rel=1e-6, abs=1e-6)


def test_the_planner_checks_agree_with_statics_result() -> None:
    gs = random_geometries(16, 3)
    d = designs_of(gs)
    payload = np.full(d.n, 0.4)
    flexion = np.full(d.n, 0.5)
    got = db.assess(d, payload, flexion)
    assert 0 < got["plan_safe"].sum() < d.n  # both kinds present: the test can tell them apart
    for i, g in enumerate(gs):
        reasons = []
        for q in (0.0, 0.5 * g.q_range_m[1]):
            r = statics.solve(g, q, statics.Load(payload_kg=0.4))
            reasons += statics.limit_violations(r) + statics.wrap_warnings(r)
        assert bool(got["plan_safe"][i]) == (not reasons), (i, reasons)


def test_stiffness_of_the_default_finger_is_the_papers_calibration() -> None:
    g = FingerGeometry.default()
    got = db.assess(designs_of([g]), np.array([3.0]), np.array([0.5]))
    curve_sag = statics.solve_batch(g, [0.0, 0.0], payload_kg=[0.0, 3.0]).tip
    sag = float(np.hypot(*(curve_sag[1] - curve_sag[0])))
    assert got["deflection_straight_m"][0] == pytest.approx(sag, rel=1e-9)
    assert got["stiffness_straight_n_per_m"][0] == pytest.approx(3 * 9.80665 / sag, rel=1e-9)


def test_swept_areas_match_the_raster_where_no_point_is_swept_twice() -> None:
    gs = random_geometries(3, 4)
    d = designs_of(gs)
    got = db.swept_areas(d)
    c = np.cumsum(1 / d.guide_radii_m, axis=1)
    for i, g in enumerate(gs):
        ref = workspace.areas(g, resolution_m=5e-4).link_areas_m2
        turns = 2 * g.q_range_m[1] * c[i]  # each link's turn over the range, rad
        for k in range(3):
            if turns[k] < 2 * math.pi:
                assert got[i, k] == pytest.approx(ref[k], rel=0.02), (i, k)
            else:  # the formula counts twice what is swept twice: never below the raster
                assert got[i, k] >= ref[k] * 0.98


def test_invalid_designs_come_back_as_nan_and_refused() -> None:
    cols = {
        "link1_m": np.array([0.07, 0.015]),  # the second: R1 + R2 >= L1
        "radius1_m": np.array([0.010, 0.010]),
    }
    out = design.evaluate({}, cols)
    assert out["valid"].tolist() == [True, False]
    assert not out["plan_safe"][1] and math.isnan(out["stiffness_straight_n_per_m"][1])
    assert math.isfinite(out["stiffness_straight_n_per_m"][0])
    assert set(design.OUTPUTS) == set(out)
