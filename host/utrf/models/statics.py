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
    generalised_forces,
    net_tensions,
    require_model,
)
from utrf.models.geometry import FingerGeometry
from utrf.models.statics_batch import (
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_RELAXATION,
    DEFAULT_THRESHOLD_M,
    RELAXATIONS,
    StaticsBatch,
    check_solver,
    solve_batch,
)
from utrf.models.statics_passes import passes_one
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

_DEFAULT_LIMITS = Limits()


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

    One case: the passes' fast path (``statics_passes.passes_one``), the passes of
    ``solve_batch`` on plain floats."""
    load = load if load is not None else Load()
    limits = limits if limits is not None else _DEFAULT_LIMITS
    if not (isinstance(q, int | float) and math.isfinite(q)):
        raise StaticsError(f"q must be a finite number of metres, got {q!r}")
    check_solver(model, relaxation, threshold_m, max_iterations)
    q = float(q)
    fx, fy = load.tip_force_n
    theta, tips, net, stretch, iterations, converged = passes_one(
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
