"""Setpoint planning: what to command so that a loaded finger lands on its target pose.

A target is a pose of the unloaded finger (a tendon displacement, a Joint-2 angle, a
normalised flexion, or the nearest reachable point to a tip position). Under load the tendons
stretch and the finger sags away from it; the plan finds the tendon displacement q to command
so that the loaded finger's tip lands on the target's tip (``match="tip"``, default) or its
Joint-2 angle on the target's (``match="theta2"``, what closed-loop control on the Joint-2
encoder does by itself), and predicts the tensions and the motor's pull there.

With one actuator a finger has one degree of freedom, so a loaded finger generally cannot
match the target's whole shape: the plan reports the remaining tip error.

The firmware closes its loop on the Joint-2 encoder and maps other target kinds to a Joint-2
angle through the rigid coupling (θ2 = q / R2). So the plan also gives the Joint-2 angle the
encoder reads when the loaded finger is on target, and the TENDON_Q and FLEXION values that
the firmware maps to that same angle (``firmware_targets``).

A plan is refused (``safe`` False, with the reasons) when the statics' own limit checks
(``statics.limit_violations``: a tendon's safety factor below the limit, a motor over its
rating, Joint 1 out of range, no convergence) find anything, or the loaded finger cannot reach
the target within ``tolerance_m``.

Named poses (``"fist"``, ...) come from the pose library (``utrf.poses``), which the caller
loads and hands to ``named_pose_target``: the models import nothing above them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from utrf.models import kinematics, statics
from utrf.models.geometry import FingerGeometry
from utrf.models.statics import Load, StaticsResult
from utrf.models.tendons import Limits

TARGET_KINDS = ("q", "theta2", "flexion", "tip")
MATCHES = ("tip", "theta2")
DEFAULT_TOLERANCE_M = 1e-3


class PlanError(ValueError):
    """A target or plan request that cannot be understood; the message names the field."""


@dataclass(frozen=True)
class Target:
    """A pose of the unloaded finger. ``value``: q in m, θ2 in rad, flexion, or tip (x, y) in m."""

    kind: str
    value: float | tuple[float, float]

    def __post_init__(self) -> None:
        if self.kind not in TARGET_KINDS:
            raise PlanError(f"Target.kind must be one of {TARGET_KINDS}, got {self.kind!r}")
        if self.kind == "tip":
            v = self.value
            if not (
                isinstance(v, tuple | list)
                and len(v) == 2
                and all(isinstance(c, int | float) and math.isfinite(c) for c in v)
            ):
                raise PlanError(f"a tip target needs finite (x, y) in m, got {v!r}")
        elif not (isinstance(self.value, int | float) and math.isfinite(self.value)):
            raise PlanError(f"a {self.kind} target needs a finite number, got {self.value!r}")

    @classmethod
    def q(cls, q_m: float) -> Target:
        return cls("q", q_m)

    @classmethod
    def theta2(cls, theta2_rad: float) -> Target:
        return cls("theta2", theta2_rad)

    @classmethod
    def flexion(cls, flexion: float) -> Target:
        return cls("flexion", flexion)

    @classmethod
    def tip(cls, x_m: float, y_m: float) -> Target:
        return cls("tip", (x_m, y_m))

    def resolve(self, geom: FingerGeometry) -> tuple[float, float]:
        """(q of the target pose, its distance from the requested tip: 0 unless kind is tip)."""
        lo, hi = geom.q_range_m
        if self.kind == "tip":
            near = kinematics.q_for_tip(geom, np.asarray(self.value, dtype=float))
            return float(near.q), float(near.distance_m)
        if isinstance(self.value, tuple | list):  # only a tip target holds (x, y)
            raise PlanError(f"a {self.kind} target needs a number, got {self.value!r}")
        if self.kind == "q":
            q = float(self.value)
        elif self.kind == "theta2":
            q = float(kinematics.q_from_theta2(geom, self.value))
        else:
            q = float(kinematics.q_from_flexion(geom, self.value))
        if not lo - 1e-12 <= q <= hi + 1e-12:
            r2lo, r2hi = geom.theta2_range_rad
            raise PlanError(
                f"target {self.kind} = {self.value!r} is outside the finger's range: q in "
                f"[{lo:g}, {hi:g}] m, theta2 in [{math.degrees(r2lo):.1f}, "
                f"{math.degrees(r2hi):.1f}] deg, flexion in "
                f"[{float(kinematics.flexion_from_q(geom, lo)):g}, 1]"
            )
        return q, 0.0

    def to_json(self) -> dict[str, Any]:
        v = self.value
        return {"kind": self.kind, "value": list(v) if isinstance(v, tuple | list) else v}


# -- named poses -------------------------------------------------------------------------------
def named_pose_target(name: str, finger: str, library: Mapping[str, Any]) -> Target:
    """Finger ``finger``'s target in the named pose of ``library`` (a ``utrf.poses.PoseLibrary``,
    which the caller loads: the pose library sits above the models, which import nothing above)."""
    try:
        pose = library[name]
    except KeyError as exc:
        raise PlanError(exc.args[0]) from None
    if finger not in pose.targets:
        raise PlanError(f"pose {name!r} has no finger {finger!r}; fingers are {list(pose.targets)}")
    t = pose.targets[finger]
    return Target(t.kind, t.value)


# -- plans --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Plan:
    """A commanded setpoint for a loaded finger, its predicted state, and whether it is safe."""

    target: Target
    match: str
    q_target_m: float  # the unloaded target pose's q
    target_tip_m: np.ndarray  # (2,) the unloaded target pose's tip
    q_command_m: float  # tendon displacement to command
    theta2_setpoint_rad: float  # Joint-2 angle of the loaded finger on target
    firmware_targets: dict[str, float]
    statics: StaticsResult  # the loaded equilibrium at q_command
    tip_error_m: float  # loaded tip to target tip
    safe: bool
    reasons: tuple[str, ...] = field(default=())
    warnings: tuple[str, ...] = field(default=())

    @property
    def motor_force_n(self) -> tuple[float, float]:
        return self.statics.motor_force_n

    @property
    def tensions_n(self) -> np.ndarray:
        return self.statics.tensions_n

    def to_json(self) -> dict[str, Any]:
        s = self.statics.to_json()
        return {
            "safe": self.safe,
            "reasons": list(self.reasons),
            "warnings": list(self.warnings),
            "target": self.target.to_json(),
            "match": self.match,
            "model": self.statics.model,
            "load": self.statics.load.to_json(),
            "q_target_m": self.q_target_m,
            "target_tip_m": self.target_tip_m.tolist(),
            "q_command_m": self.q_command_m,
            "theta2_setpoint_rad": self.theta2_setpoint_rad,
            "firmware_targets": self.firmware_targets,
            "theta_rad": s["theta_rad"],
            "tip_m": s["tip_m"],
            "tip_error_m": self.tip_error_m,
            "tensions_n": s["tensions_n"],
            "loaded_tendons": s["loaded_tendons"],
            "stress_pa": s["stress_pa"],
            "safety_factor": s["safety_factor"],
            "motor_force_n": s["motor_force_n"],
            "limits": s["limits"],
        }


def plan(
    geometry: FingerGeometry,
    target: Target,
    load: Load | None = None,
    *,
    model: str = statics.DEFAULT_MODEL,
    limits: Limits | None = None,
    match: str = "tip",
    tolerance_m: float = DEFAULT_TOLERANCE_M,
) -> Plan:
    """The q to command so that the finger under ``load`` lands on ``target`` (see module doc)."""
    load = load if load is not None else Load()
    limits = limits if limits is not None else Limits()
    statics.require_model(model)
    if match not in MATCHES:
        raise PlanError(f"match must be one of {MATCHES}, got {match!r}")
    if not (math.isfinite(tolerance_m) and tolerance_m > 0):
        raise PlanError(f"tolerance_m must be > 0, got {tolerance_m!r}")
    q_t, unreachable_by = target.resolve(geometry)
    tip_t = kinematics.tip_position(geometry, q_t)
    theta2_t = float(kinematics.theta2_from_q(geometry, q_t))
    lo, hi = geometry.q_range_m
    span = hi - lo
    window = (q_t - 0.25 * span, q_t + 0.25 * span)
    warnings: list[str] = []
    if unreachable_by > 1e-9:
        warnings.append(
            f"the requested tip is {unreachable_by * 1e3:.3f} mm from the nearest reachable "
            "point, which is the target"
        )

    def batch(q: np.ndarray) -> statics.StaticsBatch:
        return statics.solve_batch(
            geometry,
            q,
            payload_kg=load.payload_kg,
            tip_force_n=load.tip_force_n,
            tip_moment_nm=load.tip_moment_nm,
            grasp_force_n=load.grasp_force_n,
            gravity=load.gravity,
            model=model,
        )

    from scipy.optimize import brentq, minimize_scalar  # here: the CLI imports this module

    grid = np.linspace(*window, 257)
    scan = batch(grid)
    if match == "tip":
        miss = np.hypot(*(scan.tip - tip_t).T)
        i = int(np.argmin(miss))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]

        def tip_miss(q: float) -> float:
            t = batch(np.array([q])).tip[0]
            return float(np.hypot(*(t - tip_t)))

        q_cmd = float(
            minimize_scalar(tip_miss, bounds=(a, b), method="bounded", options={"xatol": 1e-10}).x
        )
    else:
        gap = scan.theta[:, 1] - theta2_t
        crossings = np.flatnonzero(np.sign(gap[:-1]) != np.sign(gap[1:]))
        if crossings.size == 0:
            raise PlanError(
                "the loaded finger's Joint-2 angle cannot reach the target within "
                f"q in [{window[0]:g}, {window[1]:g}] m"
            )
        j = int(crossings[np.argmin(np.abs(grid[crossings] - q_t))])
        q_cmd = float(
            brentq(
                lambda q: float(batch(np.array([q])).theta[0, 1]) - theta2_t,
                grid[j],
                grid[j + 1],
                xtol=1e-13,
            )
        )
    result = statics.solve(geometry, q_cmd, load, model=model, limits=limits)
    tip_error = float(np.hypot(*(result.tip_m - tip_t)))
    theta2_sp = float(result.theta_rad[1])
    r2 = geometry.guide_radii_m[1]
    firmware_targets = {
        "JOINT2_ANGLE": theta2_sp,
        "TENDON_Q": r2 * theta2_sp,
        "FLEXION": float(kinematics.flexion_from_q(geometry, r2 * theta2_sp)),
    }

    # One home for each rule: the statics' limits refuse the plan, its validity warnings warn.
    reasons = statics.limit_violations(result)
    if match == "tip" and tip_error > tolerance_m:
        reasons.append(
            f"the loaded finger's tip comes no nearer than {tip_error * 1e3:.2f} mm to the "
            f"target (tolerance {tolerance_m * 1e3:g} mm)"
        )
    warnings += statics.wrap_warnings(result)
    return Plan(
        target=target,
        match=match,
        q_target_m=q_t,
        target_tip_m=tip_t,
        q_command_m=q_cmd,
        theta2_setpoint_rad=theta2_sp,
        firmware_targets=firmware_targets,
        statics=result,
        tip_error_m=tip_error,
        safe=not reasons,
        reasons=tuple(reasons),
        warnings=tuple(warnings),
    )
