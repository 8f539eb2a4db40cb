"""Coupled kinematics of a UTRF finger (paper Sec. II-B, Eq. 1-5), vectorised over q.

The synchronous routing couples the joints: relative joint angles θ_i = q / R_i (Eq. 2).
The cumulative link angle is φ_k = Σ_{i≤k} θ_i = q · c_k with c_k = Σ_{i≤k} 1/R_i, so the tip is
x = Σ L_k cos(φ_k), y = Σ L_k sin(φ_k) (Eq. 1, 3) and the Jacobian dx/dq = −Σ L_k c_k sin φ_k,
dy/dq = Σ L_k c_k cos φ_k. (Eq. 4 as printed writes L_i / R_i where the cumulative c_k belongs;
see docs/models.md.) Every function takes scalar or array q (m) and broadcasts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from utrf.models.geometry import FingerGeometry


def _cumulative_ratios(geom: FingerGeometry) -> np.ndarray:
    return np.cumsum(1.0 / geom.R)


def joint_angles(geom: FingerGeometry, q: ArrayLike) -> np.ndarray:
    """Relative joint angles θ1..θ3 (rad), shape q.shape + (3,)."""
    q = np.asarray(q, dtype=float)
    return q[..., None] / geom.R


def joint_positions(geom: FingerGeometry, q: ArrayLike) -> np.ndarray:
    """Joint 1, Joint 2, Joint 3 and the tip (m), shape q.shape + (4, 2); Joint 1 at the origin."""
    q = np.asarray(q, dtype=float)
    phi = q[..., None] * _cumulative_ratios(geom)
    seg = geom.L * np.stack([np.cos(phi), np.sin(phi)], axis=-1).swapaxes(-1, -2)
    pts = np.cumsum(seg, axis=-1).swapaxes(-1, -2)
    origin = np.zeros((*q.shape, 1, 2))
    return np.concatenate([origin, pts], axis=-2)


def tip_position(geom: FingerGeometry, q: ArrayLike) -> np.ndarray:
    """Fingertip (x, y) in m, shape q.shape + (2,)."""
    q = np.asarray(q, dtype=float)
    phi = q[..., None] * _cumulative_ratios(geom)
    return np.stack([(geom.L * np.cos(phi)).sum(-1), (geom.L * np.sin(phi)).sum(-1)], axis=-1)


def jacobian(geom: FingerGeometry, q: ArrayLike) -> np.ndarray:
    """d(x, y)/dq (dimensionless), shape q.shape + (2,)."""
    q = np.asarray(q, dtype=float)
    c = _cumulative_ratios(geom)
    phi = q[..., None] * c
    lc = geom.L * c
    return np.stack([-(lc * np.sin(phi)).sum(-1), (lc * np.cos(phi)).sum(-1)], axis=-1)


@dataclass(frozen=True)
class ForwardResult:
    """Forward kinematics at tendon displacement(s) q."""

    q: np.ndarray
    theta: np.ndarray  # (..., 3) relative joint angles, rad
    tip: np.ndarray  # (..., 2) m
    jacobian: np.ndarray  # (..., 2) d tip / dq


def forward(geom: FingerGeometry, q: ArrayLike) -> ForwardResult:
    q = np.asarray(q, dtype=float)
    return ForwardResult(
        q=q, theta=joint_angles(geom, q), tip=tip_position(geom, q), jacobian=jacobian(geom, q)
    )


def q_from_theta2(geom: FingerGeometry, theta2: ArrayLike) -> np.ndarray:
    """Tendon displacement (m) for a Joint-2 angle (rad): q = R2 · θ2."""
    return np.asarray(theta2, dtype=float) * geom.guide_radii_m[1]


def q_from_flexion(geom: FingerGeometry, flexion: ArrayLike) -> np.ndarray:
    """Tendon displacement (m) for a normalised flexion: 0 is straight, 1 is θ1 at its maximum."""
    f = np.asarray(flexion, dtype=float)
    return f * geom.q_range_m[1]


def flexion_from_q(geom: FingerGeometry, q: ArrayLike) -> np.ndarray:
    return np.asarray(q, dtype=float) / geom.q_range_m[1]
