"""Kinematics (Eq. 1-5) against an independent chain of rigid transforms and finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from utrf.models import kinematics
from utrf.models.geometry import FingerGeometry

from .conftest import geometries


def _chain_by_matrices(geom: FingerGeometry, q: float) -> np.ndarray:
    """Joints and tip by composing homogeneous transforms, θ_i = q / R_i (Eq. 2)."""
    T = np.eye(3)
    pts = [T[:2, 2].copy()]
    for L, R in zip(geom.link_lengths_m, geom.guide_radii_m, strict=True):
        th = q / R
        rot = np.array(
            [[math.cos(th), -math.sin(th), 0], [math.sin(th), math.cos(th), 0], [0, 0, 1]]
        )
        move = np.array([[1, 0, L], [0, 1, 0], [0, 0, 1.0]])
        T = T @ rot @ move
        pts.append(T[:2, 2].copy())
    return np.array(pts)


@settings(max_examples=60, deadline=None)
@given(g=geometries(), f=st.floats(-1.0, 1.0))
def test_forward_matches_an_independent_transform_chain(g: FingerGeometry, f: float) -> None:
    q = f * g.q_range_m[1]
    expected = _chain_by_matrices(g, q)
    np.testing.assert_allclose(kinematics.joint_positions(g, q), expected, atol=1e-12)
    np.testing.assert_allclose(kinematics.tip_position(g, q), expected[-1], atol=1e-12)
    np.testing.assert_allclose(kinematics.joint_angles(g, q), q / np.array(g.guide_radii_m))


def test_forward_is_vectorised_over_any_shape(geom: FingerGeometry) -> None:
    q = np.linspace(-0.01, 0.01, 12).reshape(3, 4)
    fk = kinematics.forward(geom, q)
    assert fk.theta.shape == (3, 4, 3) and fk.tip.shape == (3, 4, 2)
    assert fk.jacobian.shape == (3, 4, 2)
    assert kinematics.joint_positions(geom, q).shape == (3, 4, 4, 2)
    for idx in np.ndindex(q.shape):
        np.testing.assert_allclose(fk.tip[idx], _chain_by_matrices(geom, q[idx])[-1], atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(g=geometries(), f=st.floats(-1.0, 1.0))
def test_jacobian_matches_finite_differences(g: FingerGeometry, f: float) -> None:
    q = f * g.q_range_m[1]
    h = 1e-7
    fd = (kinematics.tip_position(g, q + h) - kinematics.tip_position(g, q - h)) / (2 * h)
    np.testing.assert_allclose(kinematics.jacobian(g, q), fd, rtol=1e-6, atol=1e-6)


def _printed_eq4(geom: FingerGeometry, q: float) -> np.ndarray:
    """Eq. 4 as printed: L_i / R_i in front of each term, not the cumulative Σ 1/R."""
    c = np.cumsum(1.0 / geom.R)
    return np.array(
        [-(geom.L / geom.R * np.sin(q * c)).sum(), (geom.L / geom.R * np.cos(q * c)).sum()]
    )


def test_printed_eq4_is_not_the_derivative_of_eq3(geom: FingerGeometry) -> None:
    """The erratum in docs/models.md: the printed Jacobian disagrees with the finite difference."""
    q, h = 0.004, 1e-7
    fd = (kinematics.tip_position(geom, q + h) - kinematics.tip_position(geom, q - h)) / (2 * h)
    np.testing.assert_allclose(kinematics.jacobian(geom, q), fd, rtol=1e-6)
    assert np.linalg.norm(_printed_eq4(geom, q) - fd) > 0.3 * np.linalg.norm(fd)


@settings(max_examples=40, deadline=None)
@given(g=geometries(), f=st.floats(-1.0, 1.0))
def test_inverse_for_theta2_and_flexion_round_trip(g: FingerGeometry, f: float) -> None:
    q = f * g.q_range_m[1]
    th2 = kinematics.joint_angles(g, q)[1]
    assert kinematics.q_from_theta2(g, th2) == pytest.approx(q, abs=1e-15)
    assert kinematics.theta2_from_q(g, q) == pytest.approx(th2)
    assert kinematics.q_from_flexion(g, f) == pytest.approx(q, abs=1e-15)
    assert kinematics.flexion_from_q(g, q) == pytest.approx(f, abs=1e-12)
    # Flexion 1 is θ1 at the top of its range.
    assert kinematics.joint_angles(g, kinematics.q_from_flexion(g, 1.0))[0] == pytest.approx(
        g.theta1_range_rad[1]
    )


# A curve that passes within 3.4e-5 m of itself: the scan's nearest sample lay on the other
# pass (found by hypothesis in CI, 2026-11-25).
_NEAR_CROSSING = FingerGeometry(
    link_lengths_m=(0.0404957429247297, 0.044921875, 0.046875),
    guide_radii_m=(0.012869818687887613, 0.002, 0.004305815144084585),
    tendon_diameter_m=0.0011447312550494008,
    tendon_youngs_modulus_pa=5e10,
    actuating_tendon_length_m=0.25,
    link_masses_kg=(0.0, 0.0, 0.0),
    link_com_fraction=(0.0, 0.0, 0.0),
    theta1_range_rad=(-math.pi / 2, math.pi / 2),
    source="<defaults>",
)


@settings(max_examples=40, deadline=None)
@given(g=geometries(), f=st.floats(-1.0, 1.0))
@example(g=_NEAR_CROSSING, f=0.32553186262541733)
def test_q_for_tip_finds_a_point_on_the_curve(g: FingerGeometry, f: float) -> None:
    q = f * g.q_range_m[1]
    tip = kinematics.tip_position(g, q)
    near = kinematics.q_for_tip(g, tip)
    # The tip curve may cross itself, so check the tip, not the q.
    assert float(near.distance_m) < 1e-9
    np.testing.assert_allclose(kinematics.tip_position(g, near.q), tip, atol=1e-9)


def test_q_for_tip_off_the_curve_beats_a_brute_force_scan(geom: FingerGeometry) -> None:
    rng = np.random.default_rng(7)
    points = rng.uniform(-0.2, 0.2, (50, 2))
    near = kinematics.q_for_tip(geom, points)
    assert near.q.shape == (50,) and near.tip.shape == (50, 2)
    dense = kinematics.tip_position(geom, np.linspace(*geom.q_range_m, 400_001))
    for p, d, q in zip(points, near.distance_m, near.q, strict=True):
        brute = np.sqrt(((dense - p) ** 2).sum(-1)).min()
        assert d <= brute + 1e-9
        assert geom.q_range_m[0] <= q <= geom.q_range_m[1]
        assert d == pytest.approx(np.hypot(*(kinematics.tip_position(geom, q) - p)))


def test_q_for_tip_rejects_bad_points(geom: FingerGeometry) -> None:
    with pytest.raises(ValueError, match="point must be finite"):
        kinematics.q_for_tip(geom, [0.1, float("nan")])
    with pytest.raises(ValueError, match="point must be finite"):
        kinematics.q_for_tip(geom, [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="q_range"):
        kinematics.q_for_tip(geom, [0.1, 0.0], q_range=(0.01, 0.0))


@settings(max_examples=40, deadline=None)
@given(g=geometries(), th=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3))
def test_chain_positions_for_any_angles(g: FingerGeometry, th: list[float]) -> None:
    pts = kinematics.chain_positions(g, th)
    phi = np.cumsum(th)
    expected = np.cumsum(g.L[:, None] * np.column_stack([np.cos(phi), np.sin(phi)]), axis=0)
    np.testing.assert_allclose(pts[1:], expected, atol=1e-12)
    # On the coupling it agrees with the coupled chain.
    q = 0.3 * g.q_range_m[1]
    np.testing.assert_allclose(
        kinematics.chain_positions(g, kinematics.joint_angles(g, q)),
        kinematics.joint_positions(g, q),
        atol=1e-15,
    )
    with pytest.raises(ValueError, match="3 angles"):
        kinematics.chain_positions(g, [0.1, 0.2])
