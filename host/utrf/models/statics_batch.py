"""Algorithm 1 for many load cases at once, vectorised over the cases (numpy), with Aitken
relaxation where the plain iteration converges slowly; its options, checked in one place.
The model: :mod:`utrf.models.statics`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from utrf.models import kinematics, tendons
from utrf.models.equilibrium import (
    DEFAULT_MODEL,
    GRAVITY_MPS2,
    StaticsError,
    chain_points,
    chain_torques,
    configuration,
    net_tensions,
    require_model,
)
from utrf.models.geometry import FingerGeometry

DEFAULT_THRESHOLD_M = 1e-9
DEFAULT_MAX_ITERATIONS = 100
RELAXATIONS = ("auto", "none", "aitken")
DEFAULT_RELAXATION = "auto"
SLOW_CONTRACTION = 0.5  # "auto" relaxes a case whose tip movement shrinks less than this
OMEGA_BOUNDS = (0.02, 5.0)  # keep the Aitken factor sane on nonlinear steps


def check_solver(model: str, relaxation: str, threshold_m: float, max_iterations: int) -> None:
    """StaticsError naming the first bad option of Algorithm 1 (``solve``, ``solve_batch``)."""
    require_model(model)
    if relaxation not in RELAXATIONS:
        raise StaticsError(f"relaxation must be one of {RELAXATIONS}, got {relaxation!r}")
    if not (math.isfinite(threshold_m) and threshold_m > 0):
        raise StaticsError(f"threshold_m must be > 0, got {threshold_m!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise StaticsError(f"max_iterations must be an integer >= 1, got {max_iterations!r}")


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
    check_solver(model, relaxation, threshold_m, max_iterations)
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
