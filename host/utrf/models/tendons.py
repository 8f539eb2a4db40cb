"""Tendons of a UTRF finger: rest lengths (Eq. 14-15), wrap angles, stiffness, material limits.

Tendon 1 (flexion) and Tendon 4 (extension) are the actuating tendons, anchored on Link 1 and
wrapped on its guide of radius R1 at Joint 1. The coupling tendons cross between two guides:
Tendons 2 and 5 from the Base's R1 guide to Link 2's R2 guide (axes L1 apart), Tendons 3 and 6
from Link 1's R2 guide to Link 3's R3 guide (axes L2 apart). A crossed strand between guides of
radii Ra, Rb whose axes are d apart leaves each guide at arccos((Ra + Rb) / d) from the line
of centres; anchored at the far end of each guide, it wraps α0 = π − arccos((Ra + Rb) / d) on
both and spans sqrt(d² − (Ra + Rb)²) = −(Ra + Rb) tan α0, so its length is

    L_T = (α0 − tan α0) (Ra + Rb)          (Eq. 14 with the printed cot corrected to tan)

The flexion group's wraps at relative joint angles θ are α20 + θ1 and α20 − θ2 (Tendon 2),
α30 + θ2 and α30 − θ3 (Tendon 3); the extension group's are the mirror images. The routing
couples the joints (θ_i = q / R_i) only while every wrap is positive: beyond that a strand
leaves its guide and the model no longer describes the finger (see ``coupling_q_range_m``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from utrf.models.geometry import FingerGeometry

# -- assumptions the paper does not state (docs/models.md, "Limits") ------------------------
# Breaking stress on the tendon's nominal area. A 1 mm solid steel wire wrapped on a 6-10 mm
# guide would be bent to 5-8 % strain, far past yield, so the paper's "stainless steel, 1 mm"
# tendon is taken as a stranded rope. Published 7x7 AISI 304 rope of 1/16 in (1.59 mm) breaks
# at 480 lbf (2.14 kN): 1.08 GPa on the nominal circle. Rounded down to 1.0 GPa (0.79 kN for
# 1 mm).
DEFAULT_BREAKING_STRESS_PA = 1.0e9
# Design factor below which a load counts as overstressing a tendon.
DEFAULT_MIN_SAFETY_FACTOR = 2.0
# Rated pulling force of one linear motor. The paper gives only the power class (a TB6612 drives
# two linear motors, "rated load of 24 W", so about 12 W each). F = ηP/v with η ≈ 0.25 for a
# small lead-screw drive at v ≈ 20 mm/s gives 150 N. Override with the real motor's rating.
DEFAULT_ACTUATOR_RATED_FORCE_N = 150.0


@dataclass(frozen=True)
class Limits:
    """What a tendon and an actuator can take. Assumptions, documented in docs/models.md."""

    tendon_breaking_stress_pa: float = DEFAULT_BREAKING_STRESS_PA
    min_safety_factor: float = DEFAULT_MIN_SAFETY_FACTOR
    actuator_rated_force_n: float = DEFAULT_ACTUATOR_RATED_FORCE_N

    def __post_init__(self) -> None:
        for name in ("tendon_breaking_stress_pa", "min_safety_factor", "actuator_rated_force_n"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"Limits: {name} must be a number > 0, got {v!r}")

    def breaking_force_n(self, geom: FingerGeometry) -> float:
        return self.tendon_breaking_stress_pa * geom.tendon_area_m2


def straight_wrap_angle(r_a: float, r_b: float, axis_distance: float) -> float:
    """α0 = π − arccos((Ra + Rb) / d): a crossed strand's wrap on each guide when straight."""
    if not r_a + r_b < axis_distance:
        raise ValueError(
            f"a crossed strand needs Ra + Rb < d, got Ra + Rb = {r_a + r_b:g} m, "
            f"d = {axis_distance:g} m"
        )
    return math.pi - math.acos((r_a + r_b) / axis_distance)


def crossed_length(r_a: float, r_b: float, axis_distance: float) -> float:
    """Eq. 14 (tan form): wrap on both guides plus the straight crossed span, m."""
    alpha0 = straight_wrap_angle(r_a, r_b, axis_distance)
    return (alpha0 - math.tan(alpha0)) * (r_a + r_b)


def straight_wrap_angles(geom: FingerGeometry) -> np.ndarray:
    """[α20, α30] (rad) of the coupling Tendons 2 (and 5) and 3 (and 6)."""
    L, R = geom.link_lengths_m, geom.guide_radii_m
    return np.array([straight_wrap_angle(R[0], R[1], L[0]), straight_wrap_angle(R[1], R[2], L[1])])


def rest_lengths(geom: FingerGeometry) -> np.ndarray:
    """Unstretched lengths [L_T1, L_T2, L_T3] (m): the actuating tendon and Eq. 14 (tan form).

    The extension group (Tendons 4-6) mirrors the flexion group and has the same lengths.
    """
    L, R = geom.link_lengths_m, geom.guide_radii_m
    return np.array(
        [
            geom.actuating_tendon_length_m,
            crossed_length(R[0], R[1], L[0]),
            crossed_length(R[1], R[2], L[1]),
        ]
    )


def stiffnesses(geom: FingerGeometry) -> np.ndarray:
    """Axial stiffness EA / L_T (N/m) of Tendons 1-3 (and 4-6), Hooke's law (Eq. 13)."""
    return geom.tendon_youngs_modulus_pa * geom.tendon_area_m2 / rest_lengths(geom)


def wrap_angles(geom: FingerGeometry, theta: ArrayLike) -> np.ndarray:
    """Wraps (rad) at relative joint angles θ (..., 3), shape (..., 2, 4).

    Axis -2: flexion group (Tendons 2, 3), extension group (Tendons 5, 6). Axis -1: Tendon 2/5
    on the Base's R1 guide, on Link 2's R2 guide, Tendon 3/6 on Link 1's R2 guide, on Link 3's
    R3 guide. A negative wrap means the strand would leave its guide.
    """
    th = np.asarray(theta, dtype=float)
    a2, a3 = straight_wrap_angles(geom)
    t1, t2, t3 = th[..., 0], th[..., 1], th[..., 2]
    flex = np.stack([a2 + t1, a2 - t2, a3 + t2, a3 - t3], axis=-1)
    ext = np.stack([a2 - t1, a2 + t2, a3 - t2, a3 + t3], axis=-1)
    return np.stack([flex, ext], axis=-2)


def coupling_q_range_m(geom: FingerGeometry) -> tuple[float, float]:
    """Tendon displacements for which every coupling wrap stays positive on the rigid finger.

    With θ_i = q / R_i the wraps are α ± q / R_i; the binding ones are min(α20, α30) against
    the largest |θ|, at Joint 2 or 3. Symmetric in q because the groups mirror each other.
    """
    a2, a3 = straight_wrap_angles(geom)
    R = geom.guide_radii_m
    # Tendon 2: |θ1|, |θ2| < α20; Tendon 3: |θ2|, |θ3| < α30.
    q_max = min(a2 * R[0], a2 * R[1], a3 * R[1], a3 * R[2])
    return (-q_max, q_max)
