"""The statics' equations (paper Sec. III, Steps 1-3, Eq. 13 and 16): the loads on one
finger, their moments about the joints, the tendons' net tensions and stretches, and the
configuration a tendon displacement gives under them. :mod:`utrf.models.statics` iterates
them to the equilibrium (Algorithm 1); the model is described there."""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from utrf.models import kinematics, tendons
from utrf.models.geometry import FingerGeometry

GRAVITY_MPS2 = 9.80665
MODELS = ("serial", "printed")
DEFAULT_MODEL = "serial"


class StaticsError(ValueError):
    """A statics request that cannot be answered (bad input, or no convergence)."""


def require_model(model: str) -> str:
    """``model`` if it names one of :data:`MODELS`; StaticsError naming them otherwise."""
    if model not in MODELS:
        raise StaticsError(f"model must be one of {MODELS}, got {model!r}")
    return model


@dataclass(frozen=True)
class Load:
    """External loads on one finger. SI units; frame as in ``utrf.models.geometry``.

    - ``payload_kg``: a mass hanging at the tip, i.e. a tip force (0, −m g);
    - ``tip_force_n``: a tip force (Fx, Fy) of fixed direction in the finger frame;
    - ``tip_moment_nm``: a moment on Link 3, positive in flexion (+z);
    - ``grasp_force_n``: an object's reaction on the fingertip, normal to Link 3 and against
      flexion (it turns with the link);
    - ``gravity``: include the links' own weight (along −y).
    """

    payload_kg: float = 0.0
    tip_force_n: tuple[float, float] = (0.0, 0.0)
    tip_moment_nm: float = 0.0
    grasp_force_n: float = 0.0
    gravity: bool = True

    def __post_init__(self) -> None:
        for name in ("payload_kg", "tip_moment_nm", "grasp_force_n"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v)):
                raise StaticsError(f"Load: {name} must be a finite number, got {v!r}")
        if self.payload_kg < 0:
            raise StaticsError(
                f"Load: payload_kg must be >= 0, got {self.payload_kg!r} "
                "(give an upward force as tip_force_n)"
            )
        if self.grasp_force_n < 0:
            raise StaticsError(
                f"Load: grasp_force_n must be >= 0 (a push against flexion), "
                f"got {self.grasp_force_n!r}"
            )
        f = self.tip_force_n
        if (
            not isinstance(f, Sequence)
            or len(f) != 2
            or not all(isinstance(v, int | float) and math.isfinite(v) for v in f)
        ):
            raise StaticsError(f"Load: tip_force_n must be two finite numbers (Fx, Fy), got {f!r}")

    def to_json(self) -> dict[str, Any]:
        return {
            "payload_kg": self.payload_kg,
            "tip_force_n": list(self.tip_force_n),
            "tip_moment_nm": self.tip_moment_nm,
            "grasp_force_n": self.grasp_force_n,
            "gravity": self.gravity,
        }


def generalised_forces(
    geom: FingerGeometry,
    theta: ArrayLike,
    *,
    tip_force_n: ArrayLike = (0.0, 0.0),
    tip_moment_nm: ArrayLike = 0.0,
    grasp_force_n: ArrayLike = 0.0,
    gravity: bool = True,
) -> np.ndarray:
    """τ_k (N m), shape (..., 3): the moment about Joint k of the loads on Links k..3.

    Positive in flexion. ``tip_force_n`` (..., 2) is in the finger frame (a payload is
    (0, −m g)); ``grasp_force_n`` acts along Link 3's normal, against flexion.
    """
    th = np.asarray(theta, dtype=float)
    return chain_torques(
        geom,
        th,
        kinematics.chain_positions(geom, th),
        np.asarray(tip_force_n, dtype=float),
        np.asarray(tip_moment_nm, dtype=float),
        np.asarray(grasp_force_n, dtype=float),
        gravity,
    )


def chain_torques(
    geom: FingerGeometry,
    th: np.ndarray,
    pts: np.ndarray,
    tip_force: np.ndarray,
    tip_moment: np.ndarray,
    grasp: np.ndarray,
    gravity: bool,
) -> np.ndarray:
    """``generalised_forces`` with the chain's points (..., 4, 2) already computed.

    Written per joint on (...)-shaped columns rather than as (..., 3, 3) products: the same
    arithmetic in the same order, fewer passes over memory (the batch's largest cost)."""
    phi3 = th.sum(-1)
    # The grasp force pushes along Link 3's normal (−sin φ3, cos φ3), against flexion.
    fx = tip_force[..., 0] - grasp * -np.sin(phi3)
    fy = tip_force[..., 1] - grasp * np.cos(phi3)
    x0, x1, x2, x3 = (pts[..., i, 0] for i in range(4))
    y0, y1, y2, y3 = (pts[..., i, 1] for i in range(4))
    tau1 = (x3 - x0) * fy - (y3 - y0) * fx + tip_moment
    tau2 = (x3 - x1) * fy - (y3 - y1) * fx + tip_moment
    tau3 = (x3 - x2) * fy - (y3 - y2) * fx + tip_moment
    if gravity:
        # Moment about Joint k of link j's weight (0, −m_j g), j >= k: (com_j − J_k)_x (−m_j g).
        w1, w2, w3 = (-GRAVITY_MPS2 * m for m in geom.link_masses_kg)
        c1, c2, c3 = geom.link_com_fraction
        com1 = x0 + c1 * (x1 - x0)
        com2 = x1 + c2 * (x2 - x1)
        com3 = x2 + c3 * (x3 - x2)
        tau1 = tau1 + (((com1 - x0) * w1 + (com2 - x0) * w2) + (com3 - x0) * w3)
        tau2 = tau2 + ((com2 - x1) * w2 + (com3 - x1) * w3)
        tau3 = tau3 + (com3 - x2) * w3
    return np.stack(np.broadcast_arrays(tau1, tau2, tau3), axis=-1)


def chain_points(geom: FingerGeometry, th: np.ndarray) -> np.ndarray:
    """``kinematics.chain_positions`` for (n, 3) angles, column by column: the same sums in
    the same order, without cumsum's strided passes."""
    L1, L2, L3 = geom.link_lengths_m
    phi = np.empty_like(th)
    phi[:, 0] = th[:, 0]
    np.add(th[:, 0], th[:, 1], out=phi[:, 1])
    np.add(phi[:, 1], th[:, 2], out=phi[:, 2])
    cos, sin = np.cos(phi), np.sin(phi)
    pts = np.empty((th.shape[0], 4, 2))
    pts[:, 0, :] = 0.0
    np.multiply(L1, cos[:, 0], out=pts[:, 1, 0])
    np.multiply(L1, sin[:, 0], out=pts[:, 1, 1])
    pts[:, 2, 0] = pts[:, 1, 0] + L2 * cos[:, 1]
    pts[:, 2, 1] = pts[:, 1, 1] + L2 * sin[:, 1]
    pts[:, 3, 0] = pts[:, 2, 0] + L3 * cos[:, 2]
    pts[:, 3, 1] = pts[:, 2, 1] + L3 * sin[:, 2]
    return pts


def net_tensions(geom: FingerGeometry, tau: ArrayLike) -> np.ndarray:
    """N_k (N), shape (..., 3): flexion group positive, extension group negative (Steps 1-3)."""
    per_joint = -np.asarray(tau, dtype=float) / geom.R
    return per_joint[..., ::-1].cumsum(-1)[..., ::-1]


def elongations(geom: FingerGeometry, net: ArrayLike) -> np.ndarray:
    """Signed stretch e_k (m) of the loaded tendon at each level (Eq. 13)."""
    return np.asarray(net, dtype=float) / tendons.stiffnesses(geom)


def configuration(
    geom: FingerGeometry, q: ArrayLike, stretch: ArrayLike, model: str = DEFAULT_MODEL
) -> np.ndarray:
    """Relative joint angles (rad), shape (..., 3), for displacement q and tendon stretches e.

    ``serial``: R_k θ_k = q − (e1 + ... + e_k); ``printed`` (Eq. 16): R_k θ_k = q − e_k.
    """
    require_model(model)
    e = np.asarray(stretch, dtype=float)
    if model == "serial":
        e = np.cumsum(e, axis=-1)
    return (np.asarray(q, dtype=float)[..., None] - e) / geom.R


def _floats3(values: ArrayLike) -> tuple[float, float, float]:
    a, b, c = (float(v) for v in np.asarray(values, dtype=float))
    return (a, b, c)


@dataclass(frozen=True)
class FingerConstants:
    """A finger's constants for the scalar path, computed once per geometry."""

    L: tuple[float, float, float]
    R: tuple[float, float, float]
    compliance: tuple[float, float, float]
    neg_weight: tuple[float, float, float]  # −g m_k, as the batch's gravity term has it
    com: tuple[float, float, float]
    wraps: tuple[float, float]


@functools.lru_cache(maxsize=64)
def finger_constants(geom: FingerGeometry) -> FingerConstants:
    k = tendons.stiffnesses(geom)
    a2, a3 = tendons.straight_wrap_angles(geom)
    neg_g = -GRAVITY_MPS2 * np.asarray(geom.link_masses_kg)
    return FingerConstants(
        L=_floats3(geom.link_lengths_m),
        R=_floats3(geom.guide_radii_m),
        compliance=_floats3(1.0 / k),
        neg_weight=_floats3(neg_g),
        com=_floats3(geom.link_com_fraction),
        wraps=(float(a2), float(a3)),
    )
