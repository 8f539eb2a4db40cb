"""Coupled kinematics of a UTRF finger (paper Sec. II-B, Eq. 1-5), vectorised over q.

The synchronous routing couples the joints: relative joint angles θ_i = q / R_i (Eq. 2).
The cumulative link angle is φ_k = Σ_{i≤k} θ_i = q · c_k with c_k = Σ_{i≤k} 1/R_i, so the tip is
x = Σ L_k cos(φ_k), y = Σ L_k sin(φ_k) (Eq. 1, 3) and the Jacobian dx/dq = −Σ L_k c_k sin φ_k,
dy/dq = Σ L_k c_k cos φ_k. (Eq. 4 as printed writes L_i / R_i where the cumulative c_k belongs;
see docs/models.md.) Every function takes scalar or array q (m) and broadcasts.

Under load the tendons stretch and the angles leave the coupling; ``chain_positions`` gives
the joints and tip for any relative angles. ``q_for_tip`` is the inverse for a tip point: the
q within the tendon's range whose tip comes nearest.
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
    return chain_positions(geom, joint_angles(geom, q))


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
    """Normalised flexion for a tendon displacement q (m): the inverse of ``q_from_flexion``."""
    return np.asarray(q, dtype=float) / geom.q_range_m[1]


def theta2_from_q(geom: FingerGeometry, q: ArrayLike) -> np.ndarray:
    """Joint-2 angle (rad) for a tendon displacement q (m): θ2 = q / R2."""
    return np.asarray(q, dtype=float) / geom.guide_radii_m[1]


def chain_positions(geom: FingerGeometry, theta: ArrayLike) -> np.ndarray:
    """Joints 1-3 and the tip (m) for any relative angles θ (..., 3): shape (..., 4, 2)."""
    th = np.asarray(theta, dtype=float)
    if th.shape[-1:] != (3,):
        raise ValueError(f"theta must have 3 angles on its last axis, got shape {th.shape}")
    phi = np.cumsum(th, axis=-1)
    pts = np.zeros((*th.shape[:-1], 4, 2))
    pts[..., 1:, 0] = np.cumsum(geom.L * np.cos(phi), axis=-1)
    pts[..., 1:, 1] = np.cumsum(geom.L * np.sin(phi), axis=-1)
    return pts


@dataclass(frozen=True)
class NearestTip:
    """The reachable tip point nearest a requested one (arrays over the requested points)."""

    q: np.ndarray  # m
    tip: np.ndarray  # (..., 2) m
    distance_m: np.ndarray  # from the requested point


_CANDIDATES = 4  # local minima of the scan refined per point
_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


def q_for_tip(
    geom: FingerGeometry,
    point: ArrayLike,
    q_range: tuple[float, float] | None = None,
    samples: int = 4097,
) -> NearestTip:
    """The q (m) within ``q_range`` (default: the tendon's) whose tip is nearest ``point`` (..., 2).

    The reachable tip set is one curve; a dense scan picks the best sample and a golden-section
    search within its neighbours refines it (to about 1e-9 m of tip). Vectorised over points.
    """
    p = np.asarray(point, dtype=float)
    if p.shape[-1:] != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"point must be finite (x, y) in m on its last axis, got shape {p.shape}")
    lo, hi = q_range if q_range is not None else geom.q_range_m
    if not lo < hi:
        raise ValueError(f"q_range must be (min, max) with min < max, got {(lo, hi)}")
    grid = np.linspace(lo, hi, samples)
    tips = tip_position(geom, grid)  # (samples, 2)
    pts0 = p.reshape(-1, 2)
    d2 = ((pts0[:, None, :] - tips[None, :, :]) ** 2).sum(-1)
    # The curve may pass close by itself: the scan's nearest sample can lie on the wrong
    # pass. Refine the best few local minima of the scan and keep the nearest result.
    local = np.ones_like(d2, dtype=bool)
    local[:, 1:] &= d2[:, 1:] <= d2[:, :-1]
    local[:, :-1] &= d2[:, :-1] <= d2[:, 1:]
    k = min(_CANDIDATES, samples)
    cand = np.argpartition(np.where(local, d2, np.inf), k - 1, axis=1)[:, :k]  # (n, k)
    cand_d2 = np.take_along_axis(d2, cand, axis=1)
    pts = np.repeat(pts0, k, axis=0)
    best = cand.reshape(-1)
    step = grid[1] - grid[0]
    a = np.maximum(grid[best] - step, lo)
    b = np.minimum(grid[best] + step, hi)

    def dist2(q: np.ndarray) -> np.ndarray:
        return ((tip_position(geom, q) - pts) ** 2).sum(-1)

    c = b - _GOLDEN * (b - a)
    d = a + _GOLDEN * (b - a)
    fc, fd = dist2(c), dist2(d)
    for _ in range(80):
        left = fc < fd  # the minimum lies in [a, d]: drop (d, b]; else drop [a, c)
        a, b = np.where(left, a, c), np.where(left, d, b)
        new = np.where(left, b - _GOLDEN * (b - a), a + _GOLDEN * (b - a))
        f_new = dist2(new)
        c, d = np.where(left, new, d), np.where(left, c, new)
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
    q = (a + b) / 2
    # The scan's sample may itself be nearer (at a range end): keep the better.
    fq = dist2(q)
    scan_d2 = cand_d2.reshape(-1)
    keep = fq <= scan_d2
    q = np.where(keep, q, grid[best])
    fq = np.where(keep, fq, scan_d2)
    pick = fq.reshape(-1, k).argmin(axis=1)
    q = q.reshape(-1, k)[np.arange(len(pts0)), pick]
    tip = tip_position(geom, q)
    shape = p.shape[:-1]
    return NearestTip(
        q=q.reshape(shape),
        tip=tip.reshape((*shape, 2)),
        distance_m=np.sqrt(((tip - pts0) ** 2).sum(-1)).reshape(shape),
    )
