"""Tendon rest lengths (Eq. 14-15), the coupling (Eq. 2) and the moment arms, from geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from utrf.models import tendons
from utrf.models.geometry import FingerGeometry

from .conftest import geometries
from .tendon_geometry import crossed_path_length, tangent_points


@settings(max_examples=60, deadline=None)
@given(g=geometries())
def test_eq14_tan_form_is_the_straight_strand_length(g: FingerGeometry) -> None:
    L, R = g.link_lengths_m, g.guide_radii_m
    lengths = tendons.rest_lengths(g)
    assert lengths[0] == g.actuating_tendon_length_m
    for i, (ra, rb, d) in enumerate([(R[0], R[1], L[0]), (R[1], R[2], L[1])]):
        for side in ("flexion", "extension"):
            numeric, wrap_a, wrap_b = crossed_path_length(ra, rb, d, 0.0, 0.0, side)
            assert lengths[i + 1] == pytest.approx(numeric, rel=1e-12)
            alpha0 = tendons.straight_wrap_angles(g)[i]
            assert wrap_a == pytest.approx(alpha0) and wrap_b == pytest.approx(alpha0)


def test_printed_cot_form_is_shorter_than_the_span_alone(geom: FingerGeometry) -> None:
    """The erratum: with cot, Eq. 14 gives a strand shorter than its own straight span."""
    L1, R1, R2 = geom.link_lengths_m[0], geom.guide_radii_m[0], geom.guide_radii_m[1]
    a0 = math.pi - math.acos((R1 + R2) / L1)
    printed = (a0 - 1 / math.tan(a0)) * (R1 + R2)
    p_a, p_b = tangent_points(R1, R2, L1, "flexion")
    span = float(np.hypot(*(p_b - p_a)))
    assert printed < span < tendons.rest_lengths(geom)[1]
    assert span == pytest.approx(math.sqrt(L1**2 - (R1 + R2) ** 2))


@settings(max_examples=60, deadline=None)
@given(g=geometries(), u=st.floats(-0.95, 0.95), v=st.floats(-0.95, 0.95))
def test_strand_lengths_are_linear_in_the_joint_angles(
    g: FingerGeometry, u: float, v: float
) -> None:
    """ℓ_flex = L_T + R_a θ_a − R_b θ_b while the wraps stay positive; the coupling follows."""
    L, R = g.link_lengths_m, g.guide_radii_m
    alphas = tendons.straight_wrap_angles(g)
    rest = tendons.rest_lengths(g)
    for i, (ra, rb, d) in enumerate([(R[0], R[1], L[0]), (R[1], R[2], L[1])]):
        th_a, th_b = u * alphas[i], v * alphas[i]  # keeps every wrap positive
        flex, _, _ = crossed_path_length(ra, rb, d, -th_a, th_b, "flexion")
        ext, _, _ = crossed_path_length(ra, rb, d, -th_a, th_b, "extension")
        assert flex == pytest.approx(rest[i + 1] + ra * th_a - rb * th_b, abs=1e-13)
        assert ext == pytest.approx(rest[i + 1] - ra * th_a + rb * th_b, abs=1e-13)
        # Eq. 2: keeping the length while joint a turns by th_a turns joint b by R_a th_a / R_b.
        coupled = ra * th_a / rb
        if abs(coupled) < 0.95 * alphas[i]:
            same, _, _ = crossed_path_length(ra, rb, d, -th_a, coupled, "flexion")
            assert same == pytest.approx(rest[i + 1], abs=1e-13)


@settings(max_examples=40, deadline=None)
@given(g=geometries(), th=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_wrap_angles_match_the_explicit_paths(g: FingerGeometry, th: list[float]) -> None:
    L, R = g.link_lengths_m, g.guide_radii_m
    wraps = tendons.wrap_angles(g, th)
    for side, row in (("flexion", wraps[0]), ("extension", wraps[1])):
        for j, (ra, rb, d, a, b) in enumerate(
            [(R[0], R[1], L[0], th[0], th[1]), (R[1], R[2], L[1], th[1], th[2])]
        ):
            if min(row[2 * j], row[2 * j + 1]) <= 1e-6 or max(row) >= 2 * math.pi - 1e-6:
                continue  # a lifted strand: the explicit path's modulo wraps it round
            _, wa, wb = crossed_path_length(ra, rb, d, -a, b, side)
            assert (wa, wb) == pytest.approx((row[2 * j], row[2 * j + 1]), abs=1e-9)


def test_coupling_range_is_where_a_wrap_first_reaches_zero(geom: FingerGeometry) -> None:
    lo, hi = tendons.coupling_q_range_m(geom)
    assert lo == -hi
    at = tendons.wrap_angles(geom, hi / geom.R)
    assert at.min() == pytest.approx(0.0, abs=1e-12)
    assert tendons.wrap_angles(geom, 0.999 * hi / geom.R).min() > 0
    assert tendons.wrap_angles(geom, 1.001 * hi / geom.R).min() < 0


def test_stiffness_is_ea_over_length(geom: FingerGeometry) -> None:
    k = tendons.stiffnesses(geom)
    ea = 200e9 * math.pi * 0.001**2 / 4
    np.testing.assert_allclose(k, ea / tendons.rest_lengths(geom))


def test_limits_reject_nonsense() -> None:
    with pytest.raises(ValueError, match="actuator_rated_force_n"):
        tendons.Limits(actuator_rated_force_n=0)
    with pytest.raises(ValueError, match="tendon_breaking_stress_pa"):
        tendons.Limits(tendon_breaking_stress_pa=float("nan"))
    assert tendons.Limits().breaking_force_n(FingerGeometry.default()) == pytest.approx(
        1e9 * math.pi * 0.25e-6
    )


def test_a_crossed_strand_needs_room() -> None:
    with pytest.raises(ValueError, match="Ra \\+ Rb < d"):
        tendons.crossed_length(0.01, 0.01, 0.02)
