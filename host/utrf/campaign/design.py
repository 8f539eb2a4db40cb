"""The ``design`` kind: finger designs through ``utrf.models.design_batch``, many per task.

Parameters (SI; any not given takes the default finger's value, ``data/geometry/finger.toml``):
link1_m link2_m link3_m, radius1_m radius2_m radius3_m, tendon_diameter_m,
tendon_youngs_modulus_pa, actuating_tendon_length_m, link_mass_per_m (each link's mass is
this times its length), theta1_max_deg (Joint 1 moves ±this), payload_kg (at the tip, for
the stiffness, tensions and checks), flexion (the flexed pose, 0..1). Options: the limits
the checks use (``breaking_stress_pa``, ``min_safety_factor``, ``actuator_rated_force_n``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from utrf.campaign.sampling import Columns, row_count
from utrf.campaign.spec import Campaign
from utrf.models import design_batch
from utrf.models.geometry import FingerGeometry
from utrf.models.tendons import Limits

CHUNK = 20_000  # designs per task: large enough that numpy, not Python, takes the time

# name -> (lowest, highest, default): what the models describe (lengths > 0, radii below
# the links, a tendon that is a tendon); a range reaching outside is refused.
_G = FingerGeometry()
PARAMETERS: dict[str, tuple[float, float, float]] = {
    "link1_m": (1e-3, 0.5, _G.link_lengths_m[0]),
    "link2_m": (1e-3, 0.5, _G.link_lengths_m[1]),
    "link3_m": (1e-3, 0.5, _G.link_lengths_m[2]),
    "radius1_m": (1e-4, 0.1, _G.guide_radii_m[0]),
    "radius2_m": (1e-4, 0.1, _G.guide_radii_m[1]),
    "radius3_m": (1e-4, 0.1, _G.guide_radii_m[2]),
    "tendon_diameter_m": (1e-5, 0.01, _G.tendon_diameter_m),
    "tendon_youngs_modulus_pa": (1e6, 1e12, _G.tendon_youngs_modulus_pa),
    "actuating_tendon_length_m": (1e-3, 2.0, _G.actuating_tendon_length_m),
    "link_mass_per_m": (0.0, 10.0, sum(_G.link_masses_kg) / _G.total_length_m),
    "theta1_max_deg": (1.0, 180.0, math.degrees(_G.theta1_range_rad[1])),
    "payload_kg": (0.0, 100.0, 1.0),
    "flexion": (0.0, 1.0, 0.5),
}
_L = Limits()
OPTIONS = {
    "breaking_stress_pa": _L.tendon_breaking_stress_pa,
    "min_safety_factor": _L.min_safety_factor,
    "actuator_rated_force_n": _L.actuator_rated_force_n,
}
OUTPUTS = [
    "valid",
    "q_max_m",
    "theta2_max_rad",
    "theta3_max_rad",
    "coupling_q_max_m",
    "coupled_whole_range",
    "reach_m",
    "link1_area_m2",
    "link2_area_m2",
    "link3_area_m2",
    "deflection_straight_m",
    "stiffness_straight_n_per_m",
    "deflection_flexed_m",
    "stiffness_flexed_n_per_m",
    "largest_tension_n",
    "safety_factor",
    "motor_force_n",
    "converged",
    "tendons_ok",
    "motor_ok",
    "theta1_ok",
    "wraps_ok",
    "plan_safe",
]


def check(campaign: Campaign) -> None:
    for p in campaign.params:
        where = f"parameters.{p.name}"
        if p.name not in PARAMETERS:
            raise campaign.error(
                where, f"unknown design parameter {p.name!r}; known: {', '.join(PARAMETERS)}"
            )
        lo, hi, _ = PARAMETERS[p.name]
        values = (p.range.low, p.range.high) if p.range is not None else p.values or ()
        for v in values:
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise campaign.error(
                    where,
                    f"{p.name} = {v!r} is outside what the finger models describe [{lo:g}, {hi:g}]",
                )
    for key, value in campaign.options.items():
        if key not in OPTIONS:
            raise campaign.error(
                f"options.{key}", f"unknown design option {key!r}; known: {', '.join(OPTIONS)}"
            )
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise campaign.error(f"options.{key}", f"{key} must be a number > 0, got {value!r}")
    for name in campaign.objectives:
        if name not in OUTPUTS:
            raise campaign.error(
                f"objectives.{name}",
                f"unknown objective {name!r}; a design has "
                f"{', '.join(o for o in OUTPUTS if not o.endswith('_ok'))}",
            )


def designs(cols: Columns) -> tuple[design_batch.Designs, np.ndarray, np.ndarray]:
    """The designs, payloads and flexions of a task's columns (defaults filled in)."""
    n = row_count(cols)

    def col(name: str) -> np.ndarray:
        if name in cols:
            return np.asarray(cols[name], dtype=float)
        return np.full(n, PARAMETERS[name][2])

    lengths = np.column_stack([col("link1_m"), col("link2_m"), col("link3_m")])
    radii = np.column_stack([col("radius1_m"), col("radius2_m"), col("radius3_m")])
    d = design_batch.Designs(
        link_lengths_m=lengths,
        guide_radii_m=radii,
        tendon_diameter_m=col("tendon_diameter_m"),
        tendon_youngs_modulus_pa=col("tendon_youngs_modulus_pa"),
        actuating_tendon_length_m=col("actuating_tendon_length_m"),
        link_masses_kg=lengths * col("link_mass_per_m")[:, None],
        theta1_max_rad=np.radians(col("theta1_max_deg")),
    )
    return d, col("payload_kg"), col("flexion")


def evaluate(options: dict[str, Any], cols: Columns) -> Columns:
    d, payload, flexion = designs(cols)
    opts = {**OPTIONS, **options}
    limits = design_batch.DesignLimits(
        breaking_stress_pa=opts["breaking_stress_pa"],
        min_safety_factor=opts["min_safety_factor"],
        actuator_rated_force_n=opts["actuator_rated_force_n"],
    )
    return design_batch.assess(d, payload, flexion, limits)


def geometry(params: dict[str, Any], source: str = "<campaign design>") -> FingerGeometry:
    """One design's parameters as a ``FingerGeometry`` (the hand file's schema)."""
    p = {name: float(params.get(name, default)) for name, (_, _, default) in PARAMETERS.items()}
    lengths = (p["link1_m"], p["link2_m"], p["link3_m"])
    return FingerGeometry(
        link_lengths_m=lengths,
        guide_radii_m=(p["radius1_m"], p["radius2_m"], p["radius3_m"]),
        tendon_diameter_m=p["tendon_diameter_m"],
        tendon_youngs_modulus_pa=p["tendon_youngs_modulus_pa"],
        actuating_tendon_length_m=p["actuating_tendon_length_m"],
        link_masses_kg=(
            lengths[0] * p["link_mass_per_m"],
            lengths[1] * p["link_mass_per_m"],
            lengths[2] * p["link_mass_per_m"],
        ),
        link_com_fraction=(0.5, 0.5, 0.5),
        theta1_range_rad=(-math.radians(p["theta1_max_deg"]), math.radians(p["theta1_max_deg"])),
        source=source,
    )
