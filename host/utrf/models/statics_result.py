"""One equilibrium's result (:class:`StaticsResult`: tensions, stresses, safety factors,
motor forces) and its checks against the hardware's limits (:func:`check`): the one place
the statics' safety rules live; the planner (:mod:`utrf.models.planning`) asks them too."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from utrf.models.equilibrium import Load, finger_constants
from utrf.models.geometry import FingerGeometry
from utrf.models.tendons import Limits


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
        n1, n2, n3 = (float(n) for n in self.net_tensions_n)
        return (1 if n1 >= 0 else 4, 2 if n2 >= 0 else 5, 3 if n3 >= 0 else 6)

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


def check(result: StaticsResult) -> list[str]:
    """Warnings for an equilibrium: no convergence, overstress, actuator overload, validity
    (:func:`limit_violations`, then :func:`wrap_warnings`)."""
    return plain_warnings(result.geometry, result.limits, *_plain(result))


def limit_violations(result: StaticsResult) -> list[str]:
    """What makes an equilibrium unsafe to command: no convergence, a tendon below its
    safety factor, a motor above its rating, Joint 1 outside its range."""
    return _limit_violations(result.geometry, result.limits, *_plain(result))


def wrap_warnings(result: StaticsResult) -> list[str]:
    """Where the model stops holding: a coupling strand that would leave its guide."""
    return _wrap_warnings(result.geometry, _plain(result)[1])


Vec3 = tuple[float, float, float]


def _plain(result: StaticsResult) -> tuple[Vec3, Vec3, bool, int, float]:
    net, th = result.net_tensions_n, result.theta_rad
    return (
        (float(net[0]), float(net[1]), float(net[2])),
        (float(th[0]), float(th[1]), float(th[2])),
        result.converged,
        result.iterations,
        result.threshold_m,
    )


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


def plain_warnings(
    geom: FingerGeometry,
    lim: Limits,
    net: Vec3,
    theta: Vec3,
    converged: bool,
    iterations: int,
    threshold_m: float,
) -> list[str]:
    """``check`` on plain floats (the scalar path's, and ``check``'s, one implementation)."""
    n1, n2, n3 = net
    th1, th2, th3 = theta
    lo, hi = geom.theta1_range_rad
    a2, a3 = finger_constants(geom).wraps
    # The common case first: clearly nothing to report (a margin keeps it conservative).
    safe = (
        float(lim.tendon_breaking_stress_pa)
        * float(geom.tendon_area_m2)
        / lim.min_safety_factor
        * (1.0 - 1e-9)
    )
    if (
        converged
        and max(abs(n1), abs(n2), abs(n3)) < safe
        and abs(n1) <= lim.actuator_rated_force_n
        and lo <= th1 <= hi
        and abs(th1) <= a2
        and abs(th2) <= min(a2, a3)
        and abs(th3) <= a3
    ):
        return []
    return _limit_violations(
        geom, lim, net, theta, converged, iterations, threshold_m
    ) + _wrap_warnings(geom, theta)


def _limit_violations(
    geom: FingerGeometry,
    lim: Limits,
    net: Vec3,
    theta: Vec3,
    converged: bool,
    iterations: int,
    threshold_m: float,
) -> list[str]:
    n1 = net[0]
    th1 = theta[0]
    lo, hi = geom.theta1_range_rad
    # Plain floats: a numpy scalar would warn where a tiny tension gives an infinite factor.
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
            number = k + 1 if n >= 0 else k + 4
            what = "would break" if sf < 1 else "is overstressed"
            out.append(
                f"Tendon {number} {what}: {t:.1f} N, {t / area / 1e6:.0f} MPa, "
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


def _wrap_warnings(geom: FingerGeometry, theta: Vec3) -> list[str]:
    th1, th2, th3 = theta
    a2, a3 = finger_constants(geom).wraps
    if abs(th1) <= a2 and abs(th2) <= min(a2, a3) and abs(th3) <= a3:
        return []  # every strand still wraps its guides
    out: list[str] = []
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
