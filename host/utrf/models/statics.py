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

import math

import numpy as np

from utrf.models.equilibrium import (
    DEFAULT_MODEL,
    GRAVITY_MPS2,
    MODELS,
    Load,
    StaticsError,
    configuration,
    elongations,
    finger_constants,
    generalised_forces,
    net_tensions,
    require_model,
)
from utrf.models.geometry import FingerGeometry
from utrf.models.statics_batch import (
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_RELAXATION,
    DEFAULT_THRESHOLD_M,
    OMEGA_BOUNDS,
    RELAXATIONS,
    SLOW_CONTRACTION,
    StaticsBatch,
    check_solver,
    solve_batch,
)
from utrf.models.statics_result import (
    StaticsResult,
    check,
    limit_violations,
    plain_warnings,
    wrap_warnings,
)
from utrf.models.tendons import Limits

__all__ = [
    "DEFAULT_MAX_ITERATIONS",
    "DEFAULT_MODEL",
    "DEFAULT_RELAXATION",
    "DEFAULT_THRESHOLD_M",
    "GRAVITY_MPS2",
    "MODELS",
    "RELAXATIONS",
    "Load",
    "StaticsBatch",
    "StaticsError",
    "StaticsResult",
    "check",
    "configuration",
    "elongations",
    "generalised_forces",
    "limit_violations",
    "net_tensions",
    "require_model",
    "solve",
    "solve_batch",
    "wrap_warnings",
]

Vec3 = tuple[float, float, float]
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
) -> tuple[Vec3, tuple[float, float, float, float], Vec3, Vec3, int, bool]:
    """``solve_batch`` for one case on plain floats: the same passes, in the same order of
    operations (so the same numbers, up to the last bit of the trigonometric functions).

    Returns (θ, tip + unloaded tip, net tensions, stretches, iterations, converged)."""
    C = finger_constants(geom)
    L1, L2, L3 = C.L
    R1, R2, R3 = C.R
    k1, k2, k3 = C.compliance
    w1, w2, w3 = C.neg_weight
    c1, c2, c3 = C.com
    cos, sin, hypot = math.cos, math.sin, math.hypot
    lo_om, hi_om = OMEGA_BOUNDS
    slow = SLOW_CONTRACTION
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
        # Loads at the present configuration (``chain_torques``; a link's weight only turns the
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
    check_solver(model, relaxation, threshold_m, max_iterations)
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
            plain_warnings(geom, limits, net, theta, converged, iterations, threshold_m)
        ),
    )
    return result
