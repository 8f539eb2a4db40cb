"""Statics of a UTRF finger with elastic tendons (paper Sec. III, Algorithm 1), vectorised.

Equilibrium (Steps 1-3). Let τ_k be the moment about Joint k of every external load on the
links distal to it (Link k..3), positive in flexion: tip force, tip moment, the links' weight.
A tendon wrapped on a guide centred on a joint axis acts on a link through its free span,
which is tangent to the guide: its moment arm is the radius. The flexion group's Tendon k
(k = 1, 2, 3) flexes Joint k with arm R_k, and a coupling tendon extends the joint it starts
from with arm R_{k-1}. Virtual work (or the free bodies of Steps 1-3) then gives the net
tension N_k carried at level k (flexion group positive, extension group negative):

    N3 = −τ3 / R3,   N2 = N3 − τ2 / R2,   N1 = N2 − τ1 / R1

Tendons carry tension only: N_k > 0 loads Tendon k (flexion group), N_k < 0 Tendon k+3 (the
extension group), each with tension |N_k|; the other is slack.

Elasticity (Eq. 13): e_k = N_k L_Tk / (E A), with L_T1 the actuating tendon's length and
L_T2, L_T3 from Eq. 14-15 (tan form, ``utrf.models.tendons``). The configuration for a tendon
displacement q follows by one of two models:

- ``serial`` (default): the routing is a chain. Tendon 1 fixes R1 θ1 = q − e1; Tendon 2 keeps
  R2 θ2 = R1 θ1 − e2; Tendon 3 keeps R3 θ3 = R2 θ2 − e3. So R_k θ_k = q − (e1 + ... + e_k):
  a proximal stretch moves every distal joint. Its equilibrium is the minimum of the potential
  energy (tested independently), so it obeys Maxwell-Betti reciprocity.
- ``printed``: Eq. 16 as printed, each joint moved by its own tendon only: R_k θ_k = q − e_k.

Algorithm 1 iterates: configuration -> tensions -> elongations -> configuration, until the tip
moves by at most ``threshold_m`` between two passes (the paper watches the tip's y; this takes
the distance, so a load in any direction converges on the same test).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from utrf.models import kinematics, tendons
from utrf.models.geometry import FingerGeometry
from utrf.models.tendons import Limits

GRAVITY_MPS2 = 9.80665
MODELS = ("serial", "printed")
DEFAULT_MODEL = "serial"
DEFAULT_THRESHOLD_M = 1e-9
DEFAULT_MAX_ITERATIONS = 100
RELAXATIONS = ("auto", "none", "aitken")
DEFAULT_RELAXATION = "auto"
_SLOW_CONTRACTION = 0.5  # "auto" relaxes a case whose tip movement shrinks less than this
_OMEGA_BOUNDS = (0.02, 5.0)  # keep the Aitken factor sane on nonlinear steps


class StaticsError(ValueError):
    """A statics request that cannot be answered (bad input, or no convergence)."""


def require_model(model: str) -> str:
    """``model`` if it names one of ``MODELS``; a ``StaticsError`` naming the choices if not."""
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


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


_UPPER = np.triu(np.ones((3, 3)))  # [k, j]: link j is distal to (or is) link k


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
    return _torques(
        geom,
        th,
        kinematics.chain_positions(geom, th),
        np.asarray(tip_force_n, dtype=float),
        np.asarray(tip_moment_nm, dtype=float),
        np.asarray(grasp_force_n, dtype=float),
        gravity,
    )


def _torques(
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


def _chain(geom: FingerGeometry, th: np.ndarray) -> np.ndarray:
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


@dataclass(frozen=True)
class StaticsBatch:
    """Equilibria of many load cases (arrays over the cases, SI units)."""

    model: str
    q: np.ndarray  # (n,) m
    theta: np.ndarray  # (n, 3) rad
    tip: np.ndarray  # (n, 2) m
    tip_unloaded: np.ndarray  # (n, 2) m, the rigid finger's tip at q
    net_tensions_n: np.ndarray  # (n, 3) N, flexion group positive
    elongations_m: np.ndarray  # (n, 3) m, signed
    iterations: np.ndarray  # (n,) passes of Algorithm 1
    converged: np.ndarray  # (n,) bool

    @property
    def tensions_n(self) -> np.ndarray:
        """Tension (N) of the loaded tendon at each level."""
        return np.abs(self.net_tensions_n)

    @property
    def tip_deflection_m(self) -> np.ndarray:
        return np.hypot(*(self.tip - self.tip_unloaded).T)


def solve_batch(
    geom: FingerGeometry,
    q: ArrayLike,
    *,
    payload_kg: ArrayLike = 0.0,
    tip_force_n: ArrayLike = (0.0, 0.0),
    tip_moment_nm: ArrayLike = 0.0,
    grasp_force_n: ArrayLike = 0.0,
    gravity: bool = True,
    model: str = DEFAULT_MODEL,
    threshold_m: float = DEFAULT_THRESHOLD_M,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    relaxation: str = DEFAULT_RELAXATION,
) -> StaticsBatch:
    """Algorithm 1 for every case at once; arguments broadcast to a common number of cases.

    A case has converged when one plain pass of Algorithm 1 moves its tip by at most
    ``threshold_m``; it is returned at that pass's configuration. ``relaxation``: ``"none"``
    is the paper's plain iteration; ``"auto"`` (default) keeps it while it contracts and
    switches a case whose tip movement shrinks by less than half per pass (a compliant finger
    under a large load, where the plain iteration oscillates or diverges) to Aitken dynamic
    relaxation; ``"aitken"`` relaxes every case. All three stop on the same test, so they
    return the same equilibrium to within the threshold. Cases that have not converged after
    ``max_iterations`` come back with ``converged`` False (and their last iterate); ``solve``
    turns that into a warning.
    """
    require_model(model)
    if relaxation not in RELAXATIONS:
        raise StaticsError(f"relaxation must be one of {RELAXATIONS}, got {relaxation!r}")
    if not (math.isfinite(threshold_m) and threshold_m > 0):
        raise StaticsError(f"threshold_m must be > 0, got {threshold_m!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise StaticsError(f"max_iterations must be an integer >= 1, got {max_iterations!r}")
    qa = np.atleast_1d(np.asarray(q, dtype=float))
    payload = np.atleast_1d(np.asarray(payload_kg, dtype=float))
    fxy = np.atleast_2d(np.asarray(tip_force_n, dtype=float))
    moment = np.atleast_1d(np.asarray(tip_moment_nm, dtype=float))
    grasp = np.atleast_1d(np.asarray(grasp_force_n, dtype=float))
    if fxy.shape[-1] != 2:
        raise StaticsError(f"tip_force_n must be (Fx, Fy) per case, got shape {fxy.shape}")
    try:
        n = np.broadcast_shapes(qa.shape, payload.shape, fxy.shape[:-1], moment.shape, grasp.shape)
    except ValueError:
        raise StaticsError(
            "q, payload_kg, tip_force_n, tip_moment_nm and grasp_force_n must broadcast to "
            f"one number of cases; got shapes {qa.shape}, {payload.shape}, {fxy.shape}, "
            f"{moment.shape}, {grasp.shape}"
        ) from None
    if len(n) != 1:
        raise StaticsError(f"load cases must be one-dimensional, got shape {n}")
    for name, arr in (
        ("q", qa),
        ("payload_kg", payload),
        ("tip_force_n", fxy),
        ("tip_moment_nm", moment),
        ("grasp_force_n", grasp),
    ):
        if not np.all(np.isfinite(arr)):
            raise StaticsError(f"{name} must be finite")
    qa = np.broadcast_to(qa, n).copy()
    force = np.broadcast_to(fxy, (*n, 2)).copy()
    force[:, 1] -= np.broadcast_to(payload, n) * GRAVITY_MPS2
    moment = np.broadcast_to(moment, n).astype(float)
    grasp = np.broadcast_to(grasp, n).astype(float)

    compliance = 1.0 / tendons.stiffnesses(geom)
    theta = kinematics.joint_angles(geom, qa)
    pts = _chain(geom, theta)
    tip_unloaded = pts[:, 3, :].copy()
    net = np.zeros((*n, 3))
    stretch = np.zeros((*n, 3))
    iterations = np.zeros(n, dtype=int)
    converged = np.zeros(n, dtype=bool)
    # Relaxation state per case: the last plain step, its factor, the last tip movement.
    step_prev = np.zeros((*n, 3))
    omega = np.ones(n)
    change_prev = np.full(n, np.inf)
    relaxed = np.full(n, relaxation == "aitken")
    everyone = True  # while no case has converged, skip the fancy indexing
    active = np.arange(n[0])
    for k in range(1, max_iterations + 1):
        sel = slice(None) if everyone else active
        th, pts_a = theta[sel], pts[sel]
        net_a = net_tensions(
            geom, _torques(geom, th, pts_a, force[sel], moment[sel], grasp[sel], gravity)
        )
        stretch_a = net_a * compliance
        plain = configuration(geom, qa[sel], stretch_a, model)  # one pass of Algorithm 1
        pts_plain = _chain(geom, plain)
        change = np.hypot(*(pts_plain[:, 3, :] - pts_a[:, 3, :]).T)
        done = change <= threshold_m
        step = plain - th
        rel = relaxed[sel]
        if relaxation == "auto" and k >= 2:
            rel = rel | (change > _SLOW_CONTRACTION * change_prev[sel])
        om = omega[sel]
        if k >= 2 and rel.any():
            # Aitken (Irons-Tuck) factor from the last two plain steps.
            diff = step - step_prev[sel]
            denom = (diff * diff).sum(-1)
            safe = np.where(denom > 0, denom, 1.0)
            aitken = -om * (step_prev[sel] * diff).sum(-1) / safe
            om = np.where(rel & (denom > 0), np.clip(aitken, *_OMEGA_BOUNDS), om)
        move = rel & ~done
        nxt, pts_nxt = plain, pts_plain
        if move.any():
            nxt = np.where(move[:, None], th + om[:, None] * step, plain)
            pts_nxt = pts_plain.copy()
            pts_nxt[move] = _chain(geom, nxt[move])
        net[sel], stretch[sel], theta[sel], pts[sel] = net_a, stretch_a, nxt, pts_nxt
        step_prev[sel], omega[sel], change_prev[sel], relaxed[sel] = step, om, change, rel
        iterations[sel] = k
        converged[active[done]] = True
        active = active[~done]
        everyone = everyone and not done.any()
        if active.size == 0:
            break
    tip = pts[:, 3, :]
    # Each case's tensions are those of the configuration its last pass started from: the
    # same, within the threshold, as those of the returned one once converged.
    return StaticsBatch(
        model=model,
        q=qa,
        theta=theta,
        tip=tip,
        tip_unloaded=tip_unloaded,
        net_tensions_n=net,
        elongations_m=stretch,
        iterations=iterations,
        converged=converged,
    )


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass(frozen=True)
class StaticsResult:
    """One equilibrium with its tensions, stresses and warnings. SI units."""

    geometry: FingerGeometry
    load: Load
    limits: Limits
    model: str
    q_m: float
    theta_rad: np.ndarray  # (3,)
    tip_m: np.ndarray  # (2,)
    tip_unloaded_m: np.ndarray  # (2,)
    net_tensions_n: np.ndarray  # (3,) flexion group positive
    elongations_m: np.ndarray  # (3,)
    iterations: int
    converged: bool
    threshold_m: float
    warnings: tuple[str, ...] = field(default=())

    @property
    def tensions_n(self) -> np.ndarray:
        """[T1, T2, T3] of the loaded tendon at each level (Tendon k or k + 3)."""
        return np.abs(self.net_tensions_n)

    @property
    def loaded_tendons(self) -> tuple[int, int, int]:
        """Which tendon carries each level: k (flexion group) or k + 3 (extension group)."""
        return tuple(k + 1 if n >= 0 else k + 4 for k, n in enumerate(self.net_tensions_n))  # type: ignore[return-value]

    @property
    def group(self) -> str:
        t = self.loaded_tendons
        if all(i <= 3 for i in t):
            return "flexion"
        if all(i >= 4 for i in t):
            return "extension"
        return "mixed"

    @property
    def tip_deflection_m(self) -> float:
        return float(np.hypot(*(self.tip_m - self.tip_unloaded_m)))

    @property
    def stress_pa(self) -> np.ndarray:
        return self.tensions_n / self.geometry.tendon_area_m2

    @property
    def safety_factor(self) -> np.ndarray:
        """Breaking stress over stress, per level (inf for a slack level)."""
        with np.errstate(divide="ignore", over="ignore"):
            return self.limits.tendon_breaking_stress_pa / self.stress_pa

    @property
    def motor_force_n(self) -> tuple[float, float]:
        """Pull needed from motor A (Tendon 1, flexion) and motor B (Tendon 4, extension)."""
        n1 = float(self.net_tensions_n[0])
        return (max(n1, 0.0), max(-n1, 0.0))

    def to_json(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "q_m": self.q_m,
            "load": self.load.to_json(),
            "theta_rad": self.theta_rad.tolist(),
            "tip_m": self.tip_m.tolist(),
            "tip_unloaded_m": self.tip_unloaded_m.tolist(),
            "tip_deflection_m": self.tip_deflection_m,
            "tensions_n": self.tensions_n.tolist(),
            "loaded_tendons": list(self.loaded_tendons),
            "group": self.group,
            "net_tensions_n": self.net_tensions_n.tolist(),
            "elongations_m": self.elongations_m.tolist(),
            "stress_pa": self.stress_pa.tolist(),
            "safety_factor": [_finite_or_none(s) for s in self.safety_factor],
            "motor_force_n": list(self.motor_force_n),
            "iterations": self.iterations,
            "converged": self.converged,
            "threshold_m": self.threshold_m,
            "limits": {
                "tendon_breaking_stress_pa": self.limits.tendon_breaking_stress_pa,
                "min_safety_factor": self.limits.min_safety_factor,
                "actuator_rated_force_n": self.limits.actuator_rated_force_n,
            },
            "warnings": list(self.warnings),
        }


def _plain(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def check(result: StaticsResult) -> list[str]:
    """Warnings for an equilibrium: no convergence, overstress, actuator overload, validity."""
    return _warnings(
        result.geometry,
        result.limits,
        _plain(result.net_tensions_n),
        _plain(result.theta_rad),
        result.converged,
        result.iterations,
        result.threshold_m,
    )


def limit_violations(result: StaticsResult) -> list[str]:
    """The part of ``check`` that makes an equilibrium unsafe to command: no convergence, a
    tendon under its minimum safety factor, a motor over its rating, theta1 out of range."""
    return _limit_violations(
        result.geometry,
        result.limits,
        _plain(result.net_tensions_n),
        float(result.theta_rad[0]),
        result.converged,
        result.iterations,
        result.threshold_m,
    )


def wrap_warnings(result: StaticsResult) -> list[str]:
    """The part of ``check`` on the model's validity: a strand leaving its guide."""
    return _wrap_warnings(result.geometry, _plain(result.theta_rad))


_WRAP_NAMES = (
    ("Tendon 2", "Base R1 guide"),
    ("Tendon 2", "Link 2 R2 guide"),
    ("Tendon 3", "Link 1 R2 guide"),
    ("Tendon 3", "Link 3 R3 guide"),
)


@functools.lru_cache(maxsize=16)
def _limit_texts(lim: Limits) -> tuple[str, str]:
    """The limits' parts of the warnings, formatted once per ``Limits``."""
    return (
        f" < {lim.min_safety_factor:g} "
        f"(breaking stress {lim.tendon_breaking_stress_pa / 1e6:.0f} MPa assumed)",
        f", above its rated {lim.actuator_rated_force_n:g} N",
    )


def _warnings(
    geom: FingerGeometry,
    lim: Limits,
    net: tuple[float, float, float],
    theta: tuple[float, float, float],
    converged: bool,
    iterations: int,
    threshold_m: float,
) -> list[str]:
    """``check`` on plain floats (the scalar path's, and ``check``'s, one implementation)."""
    n1, n2, n3 = net
    th1, th2, th3 = theta
    lo, hi = geom.theta1_range_rad
    a2, a3 = _constants(geom).wraps
    # Plain floats: a numpy scalar would warn where a tiny tension gives an infinite factor.
    area = float(geom.tendon_area_m2)
    breaking = float(lim.tendon_breaking_stress_pa)
    # The common case first: clearly nothing to report (a margin keeps it conservative).
    safe = breaking * area / lim.min_safety_factor * (1.0 - 1e-9)
    t_max = max(abs(n1), abs(n2), abs(n3))
    if (
        converged
        and t_max < safe
        and abs(n1) <= lim.actuator_rated_force_n
        and lo <= th1 <= hi
        and abs(th1) <= a2
        and abs(th2) <= min(a2, a3)
        and abs(th3) <= a3
    ):
        return []
    return _limit_violations(geom, lim, net, th1, converged, iterations, threshold_m) + (
        _wrap_warnings(geom, theta)
    )


def _limit_violations(
    geom: FingerGeometry,
    lim: Limits,
    net: tuple[float, float, float],
    th1: float,
    converged: bool,
    iterations: int,
    threshold_m: float,
) -> list[str]:
    """``limit_violations`` on plain floats."""
    n1 = net[0]
    lo, hi = geom.theta1_range_rad
    area = float(geom.tendon_area_m2)
    breaking = float(lim.tendon_breaking_stress_pa)
    out: list[str] = []
    if not converged:
        out.append(
            f"statics did not converge to {threshold_m:g} m in {iterations} "
            "iterations: the result is the last iterate"
        )
    stress_tail, motor_tail = _limit_texts(lim)
    for k, n in enumerate(net):
        t = abs(n)
        sf = breaking / (t / area) if t > 0 else math.inf
        if sf < lim.min_safety_factor:
            tendon = k + 1 if n >= 0 else k + 4
            what = "would break" if sf < 1 else "is overstressed"
            out.append(
                f"Tendon {tendon} {what}: {t:.1f} N, {t / area / 1e6:.0f} MPa, "
                f"safety factor {sf:.2f}{stress_tail}"
            )
    if n1 > lim.actuator_rated_force_n:
        out.append(f"motor A (Tendon 1) must pull {n1:.1f} N{motor_tail}")
    if -n1 > lim.actuator_rated_force_n:
        out.append(f"motor B (Tendon 4) must pull {-n1:.1f} N{motor_tail}")
    if not lo <= th1 <= hi:
        out.append(
            f"theta1 = {math.degrees(th1):.1f} deg is outside theta1_range "
            f"[{math.degrees(lo):g}, {math.degrees(hi):g}] deg"
        )
    return out


def _wrap_warnings(geom: FingerGeometry, theta: tuple[float, float, float]) -> list[str]:
    """``wrap_warnings`` on plain floats."""
    th1, th2, th3 = theta
    a2, a3 = _constants(geom).wraps
    out: list[str] = []
    if abs(th1) <= a2 and abs(th2) <= min(a2, a3) and abs(th3) <= a3:
        return out  # every strand still wraps its guides
    wraps = ((a2 + th1, a2 - th2, a3 + th2, a3 - th3), (a2 - th1, a2 + th2, a3 - th2, a3 + th3))
    for g, group_wraps in enumerate(wraps):
        for (tendon, guide), w in zip(_WRAP_NAMES, group_wraps, strict=True):
            if w < 0:
                label = tendon if g == 0 else f"Tendon {int(tendon[-1]) + 3}"
                out.append(
                    f"{label} would leave the {guide} (wrap {math.degrees(w):.1f} deg < 0): "
                    "the routing no longer couples the joints as modelled"
                )
    return out


@dataclass(frozen=True)
class _Constants:
    """A finger's constants for the scalar path, computed once per geometry."""

    L: tuple[float, float, float]
    R: tuple[float, float, float]
    compliance: tuple[float, float, float]
    neg_weight: tuple[float, float, float]  # −g m_k, as the batch's gravity term has it
    com: tuple[float, float, float]
    wraps: tuple[float, float]


@functools.lru_cache(maxsize=64)
def _constants(geom: FingerGeometry) -> _Constants:
    k = tendons.stiffnesses(geom)
    a2, a3 = tendons.straight_wrap_angles(geom)
    neg_g = -GRAVITY_MPS2 * np.asarray(geom.link_masses_kg)
    return _Constants(
        L=tuple(float(v) for v in geom.link_lengths_m),  # type: ignore[arg-type]
        R=tuple(float(v) for v in geom.guide_radii_m),  # type: ignore[arg-type]
        compliance=tuple(float(v) for v in 1.0 / k),  # type: ignore[arg-type]
        neg_weight=tuple(float(v) for v in neg_g),  # type: ignore[arg-type]
        com=tuple(float(v) for v in geom.link_com_fraction),  # type: ignore[arg-type]
        wraps=(float(a2), float(a3)),
    )


_DEFAULT_LIMITS = Limits()


def _solve_one(
    geom: FingerGeometry,
    q: float,
    fx0: float,
    fy0: float,
    moment: float,
    grasp: float,
    gravity: bool,
    serial: bool,
    threshold_m: float,
    max_iterations: int,
    relaxation: str,
) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple[float, ...], int, bool]:
    """``solve_batch`` for one case on plain floats: the same passes, in the same order of
    operations (so the same numbers, up to the last bit of the trigonometric functions).

    Returns (θ, tip + unloaded tip, net tensions, stretches, iterations, converged)."""
    C = _constants(geom)
    L1, L2, L3 = C.L
    R1, R2, R3 = C.R
    k1, k2, k3 = C.compliance
    w1, w2, w3 = C.neg_weight
    c1, c2, c3 = C.com
    cos, sin, hypot = math.cos, math.sin, math.hypot
    lo_om, hi_om = _OMEGA_BOUNDS
    slow = _SLOW_CONTRACTION
    # The chain (``kinematics.chain_positions``) is written out where it is needed: a call
    # costs more than its arithmetic. Points: Joint 2 (x1, y1), Joint 3 (x2, y2), tip (x3, y3).
    t1, t2, t3 = q / R1, q / R2, q / R3
    a = t1 + t2
    x1, y1 = L1 * cos(t1), L1 * sin(t1)
    x2, y2 = x1 + L2 * cos(a), y1 + L2 * sin(a)
    a = a + t3
    x3, y3 = x2 + L3 * cos(a), y2 + L3 * sin(a)
    tip0x, tip0y = x3, y3
    n1 = n2 = n3 = e1 = e2 = e3 = 0.0
    sp1 = sp2 = sp3 = 0.0  # the last plain step
    omega = 1.0
    change_prev = math.inf
    relaxed = relaxation == "aitken"
    auto = relaxation == "auto"
    converged = False
    k = 0
    for k in range(1, max_iterations + 1):
        # Loads at the present configuration (``_torques``; a link's weight only turns the
        # joints proximal to it, so the batch's zero terms are left out).
        if grasp:
            a = t1 + t2 + t3
            fx = fx0 - grasp * -sin(a)
            fy = fy0 - grasp * cos(a)
        else:
            fx, fy = fx0, fy0
        tau1 = x3 * fy - y3 * fx + moment
        tau2 = (x3 - x1) * fy - (y3 - y1) * fx + moment
        tau3 = (x3 - x2) * fy - (y3 - y2) * fx + moment
        if gravity:
            m2 = x1 + c2 * (x2 - x1)
            m3 = x2 + c3 * (x3 - x2)
            tau1 = tau1 + ((c1 * x1 * w1 + m2 * w2) + m3 * w3)
            tau2 = tau2 + ((m2 - x1) * w2 + (m3 - x1) * w3)
            tau3 = tau3 + (m3 - x2) * w3
        # Net tensions and stretches (``net_tensions``, ``elongations``).
        n3 = -tau3 / R3
        n2 = n3 + -tau2 / R2
        n1 = n2 + -tau1 / R1
        e1 = n1 * k1
        e2 = n2 * k2
        e3 = n3 * k3
        # One plain pass of Algorithm 1 (``configuration``).
        if serial:
            a = e1 + e2
            p1, p2, p3 = (q - e1) / R1, (q - a) / R2, (q - (a + e3)) / R3
        else:
            p1, p2, p3 = (q - e1) / R1, (q - e2) / R2, (q - e3) / R3
        a = p1 + p2
        px1, py1 = L1 * cos(p1), L1 * sin(p1)
        px2, py2 = px1 + L2 * cos(a), py1 + L2 * sin(a)
        a = a + p3
        px3, py3 = px2 + L3 * cos(a), py2 + L3 * sin(a)
        change = hypot(px3 - x3, py3 - y3)
        done = change <= threshold_m
        st1, st2, st3 = p1 - t1, p2 - t2, p3 - t3
        rel = relaxed or (auto and k >= 2 and change > slow * change_prev)
        om = omega
        if rel and k >= 2:
            d1, d2, d3 = st1 - sp1, st2 - sp2, st3 - sp3
            denom = d1 * d1 + d2 * d2 + d3 * d3
            if denom > 0:
                aitken = -om * (sp1 * d1 + sp2 * d2 + sp3 * d3) / denom
                om = min(max(aitken, lo_om), hi_om)
        if rel and not done:
            t1, t2, t3 = t1 + om * st1, t2 + om * st2, t3 + om * st3
            a = t1 + t2
            x1, y1 = L1 * cos(t1), L1 * sin(t1)
            x2, y2 = x1 + L2 * cos(a), y1 + L2 * sin(a)
            a = a + t3
            x3, y3 = x2 + L3 * cos(a), y2 + L3 * sin(a)
        else:
            t1, t2, t3 = p1, p2, p3
            x1, y1, x2, y2, x3, y3 = px1, py1, px2, py2, px3, py3
        sp1, sp2, sp3, omega, change_prev, relaxed = st1, st2, st3, om, change, rel
        if done:
            converged = True
            break
    return (t1, t2, t3), (x3, y3, tip0x, tip0y), (n1, n2, n3), (e1, e2, e3), k, converged


def solve(
    geom: FingerGeometry,
    q: float,
    load: Load | None = None,
    *,
    model: str = DEFAULT_MODEL,
    threshold_m: float = DEFAULT_THRESHOLD_M,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    limits: Limits | None = None,
    relaxation: str = DEFAULT_RELAXATION,
) -> StaticsResult:
    """The loaded finger's equilibrium at tendon displacement q (m), with warnings.

    One case on plain floats (``_solve_one``): the passes of ``solve_batch``, about 30 times
    faster for a single case."""
    load = load if load is not None else Load()
    limits = limits if limits is not None else _DEFAULT_LIMITS
    if not (isinstance(q, int | float) and math.isfinite(q)):
        raise StaticsError(f"q must be a finite number of metres, got {q!r}")
    require_model(model)
    if relaxation not in RELAXATIONS:
        raise StaticsError(f"relaxation must be one of {RELAXATIONS}, got {relaxation!r}")
    if not (math.isfinite(threshold_m) and threshold_m > 0):
        raise StaticsError(f"threshold_m must be > 0, got {threshold_m!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise StaticsError(f"max_iterations must be an integer >= 1, got {max_iterations!r}")
    q = float(q)
    fx, fy = load.tip_force_n
    theta, tips, net, stretch, iterations, converged = _solve_one(
        geom,
        q,
        float(fx),
        float(fy) - float(load.payload_kg) * GRAVITY_MPS2,
        float(load.tip_moment_nm),
        float(load.grasp_force_n),
        load.gravity,
        model == "serial",
        threshold_m,
        max_iterations,
        relaxation,
    )
    values = np.array((*theta, *tips, *net, *stretch))  # one array, five views of it
    # The frozen dataclass's __init__ sets its 14 fields one object.__setattr__ at a time,
    # an eighth of a solve; filling the instance's dict makes the same object.
    result = object.__new__(StaticsResult)
    result.__dict__.update(
        geometry=geom,
        load=load,
        limits=limits,
        model=model,
        q_m=q,
        theta_rad=values[0:3],
        tip_m=values[3:5],
        tip_unloaded_m=values[5:7],
        net_tensions_n=values[7:10],
        elongations_m=values[10:13],
        iterations=iterations,
        converged=converged,
        threshold_m=threshold_m,
        warnings=tuple(
            _warnings(geom, limits, net, theta, converged, iterations, threshold_m)  # type: ignore[arg-type]
        ),
    )
    return result
