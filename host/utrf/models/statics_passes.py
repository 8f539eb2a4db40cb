"""Algorithm 1's passes (:mod:`utrf.models.statics`): :func:`passes`, the general path,
vectorised over the load cases, and :func:`passes_one`, its fast path for one case on plain
floats. The choice is made in one place: ``statics.solve`` (one case) runs the fast path,
``statics.solve_batch`` (any number) the general one. The fast path stays separate because
numpy's cost per call, paid on every step of a pass, would take one solve far past its 20 µs
(docs/benchmarks.md, "## Models", measures both); tests/models/test_statics.py compares the
two, pass for pass, on random fingers, loads, models and relaxations.

A pass: the loads' moments at the present configuration, the net tensions and stretches, the
configuration those stretches give (one plain pass); a case has converged when that pass moves
its tip by at most ``threshold_m``. ``relaxation``: ``"none"`` keeps the plain passes;
``"auto"`` switches a case whose tip movement shrinks by less than ``SLOW_CONTRACTION`` a pass
to Aitken relaxation; ``"aitken"`` relaxes every case.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from utrf.models import kinematics, tendons
from utrf.models.equilibrium import (
    chain_points,
    chain_torques,
    configuration,
    finger_constants,
    net_tensions,
)
from utrf.models.geometry import FingerGeometry

SLOW_CONTRACTION = 0.5  # "auto" relaxes a case whose tip movement shrinks less than this
OMEGA_BOUNDS = (0.02, 5.0)  # keep the Aitken factor sane on nonlinear steps

Vec3 = tuple[float, float, float]


class Passes(NamedTuple):
    """Where Algorithm 1 left each case (arrays over the cases, SI units)."""

    theta: np.ndarray  # (n, 3) rad
    tip: np.ndarray  # (n, 2) m
    tip_unloaded: np.ndarray  # (n, 2) m, the rigid finger's tip at q
    net: np.ndarray  # (n, 3) N, flexion group positive
    stretch: np.ndarray  # (n, 3) m, signed
    iterations: np.ndarray  # (n,) passes
    converged: np.ndarray  # (n,) bool


def passes(
    geom: FingerGeometry,
    qa: np.ndarray,
    force: np.ndarray,
    moment: np.ndarray,
    grasp: np.ndarray,
    gravity: bool,
    model: str,
    threshold_m: float,
    max_iterations: int,
    relaxation: str,
) -> Passes:
    """Algorithm 1 for (n,) cases: q (m), the tip force (n, 2) with the payload's weight in
    it, the tip moment and the grasp force; the options already checked (``check_solver``)."""
    n = qa.shape
    compliance = 1.0 / tendons.stiffnesses(geom)
    theta = kinematics.joint_angles(geom, qa)
    pts = chain_points(geom, theta)
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
            geom, chain_torques(geom, th, pts_a, force[sel], moment[sel], grasp[sel], gravity)
        )
        stretch_a = net_a * compliance
        plain = configuration(geom, qa[sel], stretch_a, model)  # one pass of Algorithm 1
        pts_plain = chain_points(geom, plain)
        change = np.hypot(*(pts_plain[:, 3, :] - pts_a[:, 3, :]).T)
        done = change <= threshold_m
        step = plain - th
        rel = relaxed[sel]
        if relaxation == "auto" and k >= 2:
            rel = rel | (change > SLOW_CONTRACTION * change_prev[sel])
        om = omega[sel]
        if k >= 2 and rel.any():
            # Aitken (Irons-Tuck) factor from the last two plain steps.
            diff = step - step_prev[sel]
            denom = (diff * diff).sum(-1)
            safe = np.where(denom > 0, denom, 1.0)
            aitken = -om * (step_prev[sel] * diff).sum(-1) / safe
            om = np.where(rel & (denom > 0), np.clip(aitken, *OMEGA_BOUNDS), om)
        move = rel & ~done
        nxt, pts_nxt = plain, pts_plain
        if move.any():
            nxt = np.where(move[:, None], th + om[:, None] * step, plain)
            pts_nxt = pts_plain.copy()
            pts_nxt[move] = chain_points(geom, nxt[move])
        net[sel], stretch[sel], theta[sel], pts[sel] = net_a, stretch_a, nxt, pts_nxt
        step_prev[sel], omega[sel], change_prev[sel], relaxed[sel] = step, om, change, rel
        iterations[sel] = k
        converged[active[done]] = True
        active = active[~done]
        everyone = everyone and not done.any()
        if active.size == 0:
            break
    # Each case's tensions are those of the configuration its last pass started from: the
    # same, within the threshold, as those of the returned one once converged.
    return Passes(theta, pts[:, 3, :], tip_unloaded, net, stretch, iterations, converged)


def passes_one(
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
    """The fast path of :func:`passes` for one case, on plain floats: the same passes, in the
    same order of operations (so the same numbers, up to the last bit of the trigonometric
    functions). ``fy0`` holds the payload's weight; ``serial``: the serial model.

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
