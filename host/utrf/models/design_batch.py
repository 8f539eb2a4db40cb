"""Many finger designs at once: the models of one finger, vectorised over designs (numpy).

Where ``kinematics``, ``tendons``, ``statics_batch`` and ``workspace`` take one geometry and
many poses, this takes many geometries (arrays of link lengths, guide radii, tendons) and,
per design: the coupling (ranges, the wrap-limited range), the areas swept by each link
(Fig. 3), the tip stiffness under a payload at the straight pose and at a flexed pose
(Algorithm 1, serial model, as ``statics_batch``), the largest tendon tension and the
statics' limit checks that the planner refuses a load on (``statics_result``). The same
equations as the one-geometry models, written over a design axis; tests compare the two.

Areas: link k at tendon displacement q spans p(q, s) = J_k(q) + s u(φ_k), s in [0, L_k].
By the area formula its swept area is ∫∫ |det ∂p/∂(q, s)| ds dq = ∫ ∫_0^{L_k} |a_k(q) + s c_k|
ds dq with a_k = Σ_{i<k} L_i c_i cos((c_k − c_i) q); the inner integral is closed-form, the
outer a trapezoid rule. Exact where the sweep covers no point twice; where it does (a link
turning more than a full turn over the range, as Link 3 of the default finger does) the
formula counts the twice-covered area twice: 2.8 % high on the default's Link 3 against
``workspace.areas``' raster (docs/campaigns.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GRAVITY_MPS2 = 9.80665
AREA_Q_POINTS = 33  # trapezoid nodes over half the tendon's range (the integrand is even in q)
MAX_ITERATIONS = 100
THRESHOLD_M = 1e-9


@dataclass(frozen=True)
class Designs:
    """Arrays of shape (n,) in SI units; one design per index."""

    link_lengths_m: np.ndarray  # (n, 3)
    guide_radii_m: np.ndarray  # (n, 3)
    tendon_diameter_m: np.ndarray
    tendon_youngs_modulus_pa: np.ndarray
    actuating_tendon_length_m: np.ndarray
    link_masses_kg: np.ndarray  # (n, 3)
    theta1_max_rad: np.ndarray  # the range is ±theta1_max_rad

    @property
    def n(self) -> int:
        return int(self.link_lengths_m.shape[0])

    def valid(self) -> np.ndarray:
        """A crossed coupling tendon needs R_i + R_{i+1} < L_i (``FingerGeometry``'s rule)."""
        L, R = self.link_lengths_m, self.guide_radii_m
        return (R[:, 0] + R[:, 1] < L[:, 0]) & (R[:, 1] + R[:, 2] < L[:, 1])


def straight_wraps(d: Designs) -> np.ndarray:
    """[α20, α30] per design (n, 2): ``tendons.straight_wrap_angles``; NaN where invalid."""
    L, R = d.link_lengths_m, d.guide_radii_m
    with np.errstate(invalid="ignore"):
        a2 = np.pi - np.arccos((R[:, 0] + R[:, 1]) / L[:, 0])
        a3 = np.pi - np.arccos((R[:, 1] + R[:, 2]) / L[:, 1])
    return np.stack([a2, a3], axis=-1)


def compliances(d: Designs, wraps: np.ndarray) -> np.ndarray:
    """1 / (EA / L_T) of Tendons 1-3 per design (n, 3): ``tendons.stiffnesses`` inverted."""
    R = d.guide_radii_m
    sums = np.stack([R[:, 0] + R[:, 1], R[:, 1] + R[:, 2]], axis=-1)
    crossed = (wraps - np.tan(wraps)) * sums  # Eq. 14, tan form
    lengths = np.column_stack([d.actuating_tendon_length_m, crossed])
    ea = d.tendon_youngs_modulus_pa * np.pi * d.tendon_diameter_m**2 / 4.0
    return lengths / ea[:, None]


def coupling_q_max(d: Designs, wraps: np.ndarray) -> np.ndarray:
    """``tendons.coupling_q_range_m``'s upper end per design."""
    R = d.guide_radii_m
    a2, a3 = wraps[:, 0], wraps[:, 1]
    return np.minimum.reduce([a2 * R[:, 0], a2 * R[:, 1], a3 * R[:, 1], a3 * R[:, 2]])


def swept_areas(d: Designs, q_points: int = AREA_Q_POINTS) -> np.ndarray:
    """Area (m²) swept by each link over q in ±θ1max R1, per design (n, 3)."""
    L, R = d.link_lengths_m, d.guide_radii_m
    c = np.cumsum(1.0 / R, axis=1)
    q_max = d.theta1_max_rad * R[:, 0]
    # a_k(q) is even in q and the range symmetric: integrate over [0, q_max], twice
    q = q_max[:, None] * np.linspace(0.0, 1.0, q_points)[None, :]  # (n, m)
    out = np.empty((d.n, 3))
    out[:, 0] = 2 * q_max * c[:, 0] * L[:, 0] ** 2 / 2  # a sector: Δθ1 L1² / 2
    for k in (1, 2):
        b = c[:, k : k + 1]
        a = np.zeros_like(q)
        for i in range(k):
            a += (L[:, i] * c[:, i])[:, None] * np.cos((c[:, k] - c[:, i])[:, None] * q)
        lk = L[:, k : k + 1]
        full = a * lk + b * lk**2 / 2  # ∫_0^L (a + b s) ds
        inner = np.where(a >= 0, full, np.where(a + b * lk <= 0, -full, full + a * a / b))
        out[:, k] = 2 * np.trapezoid(inner, q, axis=1)
    return out


@dataclass(frozen=True)
class Equilibria:
    theta: np.ndarray  # (n, 3) rad
    tip: np.ndarray  # (n, 2) m
    net_tensions_n: np.ndarray  # (n, 3)
    converged: np.ndarray  # (n,)


def _points(L: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    phi = np.cumsum(theta, axis=1)
    x = np.cumsum(L * np.cos(phi), axis=1)
    y = np.cumsum(L * np.sin(phi), axis=1)
    return x, y  # (n, 3) each: Joints 2, 3 and the tip


def equilibrium(
    d: Designs, q: np.ndarray, payload_kg: np.ndarray, compliance: np.ndarray
) -> Equilibria:
    """Algorithm 1 (serial model, plain iteration) per design, at tendon displacement q with
    a payload at the tip and the links' weight (centres at mid-link). Each design stops when
    a pass moves its tip by at most ``THRESHOLD_M`` (then it is returned at that pass)."""
    theta = q[:, None] / d.guide_radii_m
    tip = np.zeros((d.n, 2))
    net = np.zeros_like(theta)
    converged = np.zeros(d.n, dtype=bool)
    active = np.arange(d.n)
    L, R, m = d.link_lengths_m, d.guide_radii_m, d.link_masses_kg
    w = -GRAVITY_MPS2 * m
    fy = -GRAVITY_MPS2 * payload_kg
    x, y = _points(L, theta)
    for _ in range(MAX_ITERATIONS):
        a = active
        xa, ya = x[a], y[a]
        j = np.column_stack([np.zeros(a.size), xa[:, :2]])  # Joint k's x (Joint 1 at 0)
        ends = np.column_stack([np.zeros(a.size), xa])
        com = (ends[:, :3] + ends[:, 1:]) / 2  # link centres' x
        wa, fa, ra = w[a], fy[a], R[a]
        tau = np.empty((a.size, 3))
        for k in range(3):
            tau[:, k] = (xa[:, 2] - j[:, k]) * fa + ((com[:, k:] - j[:, k : k + 1])
                                                      * wa[:, k:]).sum(1)  # fmt: skip
        n_a = np.cumsum((-tau / ra)[:, ::-1], axis=1)[:, ::-1]
        th = (q[a, None] - np.cumsum(n_a * compliance[a], axis=1)) / ra
        nx, ny = _points(L[a], th)
        done = np.hypot(nx[:, 2] - xa[:, 2], ny[:, 2] - ya[:, 2]) <= THRESHOLD_M
        net[a], theta[a], x[a], y[a] = n_a, th, nx, ny
        converged[a[done]] = True
        active = a[~done]
        if active.size == 0:
            break
    tip[:, 0], tip[:, 1] = x[:, 2], y[:, 2]
    return Equilibria(theta, tip, net, converged)


@dataclass(frozen=True)
class DesignLimits:
    """``tendons.Limits`` per design (arrays or scalars)."""

    breaking_stress_pa: np.ndarray | float = 1.0e9
    min_safety_factor: np.ndarray | float = 2.0
    actuator_rated_force_n: np.ndarray | float = 150.0


def assess(
    d: Designs,
    payload_kg: np.ndarray,
    flexion: np.ndarray,
    limits: DesignLimits | None = None,
) -> dict[str, np.ndarray]:
    """Per design: coupling, swept areas, stiffness straight and flexed, the largest tension
    and the planner's limit checks, with ``payload_kg`` at the tip; the flexed pose is at
    ``flexion`` (0 straight, 1 at θ1's upper limit). Invalid designs (``valid`` False) come
    back with NaN figures and every check False."""
    lim = limits or DesignLimits()
    valid = d.valid()
    if not valid.all():  # the others are no finger: NaN figures, every check False
        part = assess(_subset(d, valid), payload_kg[valid], flexion[valid], _limits_at(lim, valid))
        filled: dict[str, np.ndarray] = {}
        for name, col in part.items():
            full = np.zeros(d.n, dtype=bool) if col.dtype == bool else np.full(d.n, np.nan)
            full[valid] = col
            filled[name] = full
        filled["valid"] = valid
        return filled
    wraps = straight_wraps(d)
    R = d.guide_radii_m
    q_max = d.theta1_max_rad * R[:, 0]
    q_couple = coupling_q_max(d, wraps)
    compliance = compliances(d, wraps)
    areas = swept_areas(d)
    zero = np.zeros(d.n)
    out: dict[str, np.ndarray] = {
        "valid": valid,
        "q_max_m": q_max,
        "theta2_max_rad": q_max / R[:, 1],
        "theta3_max_rad": q_max / R[:, 2],
        "coupling_q_max_m": q_couple,
        "coupled_whole_range": q_couple >= q_max,
        "reach_m": d.link_lengths_m.sum(axis=1),
        "link1_area_m2": areas[:, 0],
        "link2_area_m2": areas[:, 1],
        "link3_area_m2": areas[:, 2],
    }
    breaking = lim.breaking_stress_pa * np.pi * d.tendon_diameter_m**2 / 4.0
    largest = np.zeros(d.n)
    motor = np.zeros(d.n)
    converged = np.ones(d.n, dtype=bool)
    theta1_ok = np.ones(d.n, dtype=bool)
    wraps_ok = np.ones(d.n, dtype=bool)
    for pose, q in (("straight", zero), ("flexed", flexion * q_max)):
        rest = equilibrium(d, q, zero, compliance)
        loaded = equilibrium(d, q, payload_kg, compliance)
        sag = np.hypot(*(loaded.tip - rest.tip).T)
        with np.errstate(divide="ignore"):
            out[f"deflection_{pose}_m"] = sag
            out[f"stiffness_{pose}_n_per_m"] = np.where(
                sag > 0, payload_kg * GRAVITY_MPS2 / np.where(sag > 0, sag, 1.0), np.inf
            )
        largest = np.maximum(largest, np.abs(loaded.net_tensions_n).max(axis=1))
        motor = np.maximum(motor, np.abs(loaded.net_tensions_n[:, 0]))
        converged &= loaded.converged & rest.converged
        th = loaded.theta
        theta1_ok &= np.abs(th[:, 0]) <= d.theta1_max_rad
        a2, a3 = wraps[:, 0], wraps[:, 1]
        wraps_ok &= (
            (np.abs(th[:, 0]) <= a2) & (np.abs(th[:, 1]) <= np.minimum(a2, a3))
            & (np.abs(th[:, 2]) <= a3)
        )  # fmt: skip
    with np.errstate(divide="ignore"):
        safety = np.where(largest > 0, breaking / np.where(largest > 0, largest, 1.0), np.inf)
    checks = {
        "converged": converged,
        "tendons_ok": safety >= lim.min_safety_factor,
        "motor_ok": motor <= lim.actuator_rated_force_n,
        "theta1_ok": theta1_ok,
        "wraps_ok": wraps_ok,
    }
    out.update(
        largest_tension_n=largest,
        safety_factor=safety,
        motor_force_n=motor,
        **checks,
        plan_safe=np.logical_and.reduce(list(checks.values())),
    )
    return out


def _subset(d: Designs, sel: np.ndarray) -> Designs:
    return Designs(*(getattr(d, f)[sel] for f in d.__dataclass_fields__))


def _limits_at(lim: DesignLimits, sel: np.ndarray) -> DesignLimits:
    def pick(v: np.ndarray | float) -> np.ndarray | float:
        return v[sel] if isinstance(v, np.ndarray) else v

    return DesignLimits(*(pick(getattr(lim, f)) for f in lim.__dataclass_fields__))
