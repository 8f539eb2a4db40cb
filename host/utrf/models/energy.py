"""An independent solution of the ``serial`` statics: minimum of the potential energy.

Algorithm 1 (``utrf.models.statics``) balances moments link by link and iterates on the
configuration. Here the same finger is a conservative system in its three relative joint
angles, and its equilibrium is the minimum of

    V(θ) = Σ_k ½ k_k s_k(θ)² + Σ_j m_j g y_j(θ) − F · p_tip(θ) − M φ3(θ)

where s_k is the stretch of level k's tendon pair (s1 = q − R1 θ1, s2 = R1 θ1 − R2 θ2,
s3 = R2 θ2 − R3 θ3, from the routing; s > 0 stretches the flexion tendon, s < 0 the
extension tendon, and a tendon under compression is slack: each side stores ½ k max(±s, 0)²).
Positions come from composing planar rigid transforms (not from ``utrf.models.kinematics``),
the gradient from complex-step differentiation of V (exact to rounding, no hand-derived
moments), and scipy's BFGS finds the minimum. Tensions are then k_k s_k.

Only fixed-direction loads are conservative: a grasp force (which turns with Link 3) is not
accepted here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from utrf.models import tendons
from utrf.models.geometry import FingerGeometry
from utrf.models.statics import GRAVITY_MPS2, Load, StaticsError


def _transform(angle: complex | float, length: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, length * c], [s, c, length * s], [0.0, 0.0, 1.0]], dtype=complex)


def _frames(geom: FingerGeometry, theta: np.ndarray) -> list[np.ndarray]:
    """World transform of each link's frame (origin at its joint, x along the link)."""
    frames = []
    world = np.eye(3, dtype=complex)
    prev_len = 0.0
    for k in range(3):
        # Move along the previous link to Joint k, then turn by θ_k.
        world = world @ _transform(0.0, prev_len) @ _transform(theta[k], 0.0)
        frames.append(world)
        prev_len = geom.link_lengths_m[k]
    return frames


def _stretches(geom: FingerGeometry, q: float, theta: np.ndarray) -> list:
    R = geom.guide_radii_m
    return [
        q - R[0] * theta[0],
        R[0] * theta[0] - R[1] * theta[1],
        R[1] * theta[1] - R[2] * theta[2],
    ]


def tendon_potential(geom: FingerGeometry, q: float, theta: np.ndarray) -> complex:
    """Elastic energy (J) of the stretched tendons; a compressed tendon is slack."""
    v: complex = 0.0
    for kk, sk in zip(tendons.stiffnesses(geom), _stretches(geom, q, theta), strict=True):
        stretched = (sk.real if isinstance(sk, complex) else sk) > 0
        flexion_side = sk if stretched else 0.0  # Tendon k stretched by s
        extension_side = 0.0 if stretched else -sk  # Tendon k + 3 stretched by -s
        v += 0.5 * kk * flexion_side * flexion_side + 0.5 * kk * extension_side * extension_side
    return v


def load_potential(geom: FingerGeometry, load: Load, theta: np.ndarray) -> complex:
    """Potential (J) of the fixed-direction loads; accepts complex θ."""
    if load.grasp_force_n != 0:
        raise StaticsError("the energy check takes conservative loads only (grasp_force_n = 0)")
    frames = _frames(geom, theta)
    tip = frames[2] @ np.array([geom.link_lengths_m[2], 0.0, 1.0])
    fx, fy = load.tip_force_n
    fy = fy - load.payload_kg * GRAVITY_MPS2
    v: complex = -(fx * tip[0] + fy * tip[1])
    v -= load.tip_moment_nm * (theta[0] + theta[1] + theta[2])
    if load.gravity:
        for j in range(3):
            com = frames[j] @ np.array(
                [geom.link_com_fraction[j] * geom.link_lengths_m[j], 0.0, 1.0]
            )
            v += geom.link_masses_kg[j] * GRAVITY_MPS2 * com[1]
    return v


def potential(geom: FingerGeometry, q: float, load: Load, theta: np.ndarray) -> complex:
    """V(θ) in J; accepts complex θ for complex-step differentiation."""
    return tendon_potential(geom, q, theta) + load_potential(geom, load, theta)


def _complex_step_gradient(f: Callable[[np.ndarray], complex], theta: np.ndarray) -> np.ndarray:
    h = 1e-30
    g = np.empty(3)
    for i in range(3):
        t = np.asarray(theta, dtype=complex).copy()
        t[i] += 1j * h
        g[i] = f(t).imag / h
    return g


def load_torques(geom: FingerGeometry, load: Load, theta: np.ndarray) -> np.ndarray:
    """Generalised forces of the loads, −∂V_load/∂θ (N m, flexion positive), by complex step."""
    return -_complex_step_gradient(lambda t: load_potential(geom, load, t), theta)


@dataclass(frozen=True)
class EnergySolution:
    theta: np.ndarray  # (3,) rad
    tip: np.ndarray  # (2,) m
    net_tensions_n: np.ndarray  # (3,) N, flexion group positive
    gradient_norm: float  # N m, at the minimum


def solve_energy(geom: FingerGeometry, q: float, load: Load) -> EnergySolution:
    """Equilibrium of the serial model as the minimum of V, started from the rigid pose."""
    theta0 = np.asarray(q, dtype=float) / geom.R

    def fun(x: np.ndarray) -> float:
        return float(potential(geom, q, load, x).real)

    def jac(x: np.ndarray) -> np.ndarray:
        return _complex_step_gradient(lambda t: potential(geom, q, load, t), x)

    from scipy.optimize import minimize  # here: the CLI imports this module at every start

    res = minimize(fun, theta0, jac=jac, method="BFGS", options={"gtol": 1e-10, "maxiter": 500})
    theta = np.asarray(res.x, dtype=float)
    s = np.array(_stretches(geom, q, theta))
    tip = (_frames(geom, theta)[2] @ np.array([geom.link_lengths_m[2], 0.0, 1.0])).real[:2]
    return EnergySolution(
        theta=theta,
        tip=tip,
        net_tensions_n=tendons.stiffnesses(geom) * s,
        gradient_norm=float(np.linalg.norm(jac(theta))),
    )
