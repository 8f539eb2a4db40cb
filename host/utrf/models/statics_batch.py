"""Algorithm 1 for many load cases at once: the cases checked and broadcast, the passes
(:func:`~utrf.models.statics_passes.passes`) run on them all, and Algorithm 1's options,
checked in one place. The model: :mod:`utrf.models.statics`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from utrf.models.equilibrium import DEFAULT_MODEL, GRAVITY_MPS2, StaticsError, require_model
from utrf.models.geometry import FingerGeometry
from utrf.models.statics_passes import passes

DEFAULT_THRESHOLD_M = 1e-9
DEFAULT_MAX_ITERATIONS = 100
RELAXATIONS = ("auto", "none", "aitken")
DEFAULT_RELAXATION = "auto"


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

    found = passes(
        geom, qa, force, moment, grasp, gravity, model, threshold_m, max_iterations, relaxation
    )
    return StaticsBatch(
        model=model,
        q=qa,
        theta=found.theta,
        tip=found.tip,
        tip_unloaded=found.tip_unloaded,
        net_tensions_n=found.net,
        elongations_m=found.stretch,
        iterations=found.iterations,
        converged=found.converged,
    )
