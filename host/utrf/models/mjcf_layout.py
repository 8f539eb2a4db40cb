"""The MJCF's layout: ``utrf/data/mjcf.toml`` read and checked (palm, finger placement,
motors, contact, dynamics constants): everything the hand's MuJoCo model needs beyond the
geometry files. Errors name the file, the table and the field. ``utrf.models.mjcf`` builds the
model from it and re-exports every name here."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from utrf.models.geometry import package_data, read_toml

INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")


class MjcfError(ValueError):
    """A layout or hand that cannot be turned into a MuJoCo model; the message names it."""


@dataclass(frozen=True)
class FingerPlacement:
    """Where a finger's Joint 1 sits on the palm and how its frame is turned."""

    position_m: tuple[float, float, float]
    yaw_rad: float
    roll_rad: float
    pitch_rad: float = 0.0

    def rotation(self) -> np.ndarray:
        """Finger frame axes (columns x, y, z) in the palm frame: yaw about the palm's z, then
        pitch (positive: the finger's axis tilts up out of the palm's plane), then roll about
        the finger's own axis."""
        cy, sy = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        cp, sp = math.cos(self.pitch_rad), math.sin(self.pitch_rad)
        cr, sr = math.cos(self.roll_rad), math.sin(self.roll_rad)
        yaw = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        # Positive pitch turns the axis from +x toward +z (about the palm's −y).
        pitch = np.array([[cp, 0.0, -sp], [0.0, 1.0, 0.0], [sp, 0.0, cp]])
        # The finger's (x, y, z) at yaw = roll = 0 is (x, z, −y) of the palm: it flexes up.
        base = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
        roll = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        return yaw @ pitch @ base @ roll

    def quat(self) -> np.ndarray:
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, self.rotation().flatten())
        return q


@dataclass(frozen=True)
class MotorConstants:
    stall_force_n: float
    no_load_speed_m_s: float
    moving_mass_kg: float
    coulomb_friction_n: float
    viscous_friction_n_s_m: float
    stroke_m: tuple[float, float]
    peak_force_n: float  # the force bound: a back-driven motor brakes with more than stall


@dataclass(frozen=True)
class Dynamics:
    timestep_s: float
    integrator: str
    gravity_m_s2: float
    joint_damping_n_m_s: float
    coupling_damping_n_s_m: float


@dataclass(frozen=True)
class Layout:
    """``utrf/data/mjcf.toml``: everything the MJCF needs beyond the geometry files."""

    palm_size_m: tuple[float, float, float]
    palm_mass_kg: float
    link_radius_fraction: float
    friction: tuple[float, float, float]
    fingers: Mapping[str, FingerPlacement]
    motor: MotorConstants
    pulley_radius_m: float
    dynamics: Dynamics
    source: str = "<layout>"


def _num(table: Mapping[str, Any], key: str, where: str, *, bound: str = "positive") -> float:
    """A finite number; ``bound``: "positive" (> 0), "nonnegative" (>= 0) or "any"."""
    v = table.get(key)
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        raise MjcfError(f"{where}: {key} must be a finite number, got {v!r}")
    if bound == "positive" and v <= 0:
        raise MjcfError(f"{where}: {key} must be > 0, got {v!r}")
    if bound == "nonnegative" and v < 0:
        raise MjcfError(f"{where}: {key} must be >= 0, got {v!r}")
    return float(v)


def _vec(table: Mapping[str, Any], key: str, where: str, n: int) -> tuple[float, ...]:
    v = table.get(key)
    if (
        not isinstance(v, Sequence)
        or isinstance(v, str)
        or len(v) != n
        or not all(isinstance(x, int | float) and math.isfinite(x) for x in v)
    ):
        raise MjcfError(f"{where}: {key} must be a list of {n} finite numbers, got {v!r}")
    return tuple(float(x) for x in v)


def _table(doc: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any]:
    t = doc.get(key)
    if not isinstance(t, dict):
        raise MjcfError(f"{where}: needs a [{key}] table")
    return t


def load_layout(path: str | Path | None = None) -> Layout:
    """Read a layout TOML (default: the package's ``data/mjcf.toml``)."""
    if path is None:
        with package_data("mjcf.toml") as p:
            return load_layout(p)
    path = Path(path)
    doc = read_toml(path, "MJCF layout", MjcfError)
    src = str(path)
    palm = _table(doc, "palm", src)
    links = _table(doc, "links", src)
    contact = _table(doc, "contact", src)
    fingers = _table(doc, "fingers", src)
    motor = _table(doc, "motor", src)
    rotary = _table(doc, "rotary", src)
    dyn = _table(doc, "dynamics", src)
    placements = {}
    for name, t in fingers.items():
        where = f"{src} [fingers.{name}]"
        if not isinstance(t, dict):
            raise MjcfError(f"{where}: must be a table")
        placements[name] = FingerPlacement(
            position_m=_vec(t, "position_m", where, 3),  # type: ignore[arg-type]  # _vec checked the length
            yaw_rad=math.radians(_num(t, "yaw_deg", where, bound="any")),
            roll_rad=math.radians(_num(t, "roll_deg", where, bound="any")),
            pitch_rad=math.radians(_num({"pitch_deg": 0.0, **t}, "pitch_deg", where, bound="any")),
        )
    size = _vec(palm, "size_m", f"{src} [palm]", 3)
    if min(size) <= 0:
        raise MjcfError(f"{src} [palm]: size_m must be > 0, got {list(size)}")
    friction = _vec(contact, "friction", f"{src} [contact]", 3)
    if min(friction) < 0:
        raise MjcfError(f"{src} [contact]: friction must be >= 0, got {list(friction)}")
    stroke = _vec(motor, "stroke_m", f"{src} [motor]", 2)
    if not stroke[0] < 0 < stroke[1]:
        raise MjcfError(f"{src} [motor]: stroke_m must be [min < 0, max > 0], got {list(stroke)}")
    integrator = dyn.get("integrator")
    if integrator not in INTEGRATORS:
        raise MjcfError(
            f"{src} [dynamics]: integrator must be one of {INTEGRATORS}, got {integrator!r}"
        )
    w = f"{src} [motor]"
    d = f"{src} [dynamics]"
    return Layout(
        palm_size_m=size,  # type: ignore[arg-type]  # _vec checked the length
        palm_mass_kg=_num(palm, "mass_kg", f"{src} [palm]"),
        link_radius_fraction=_num(links, "radius_fraction", f"{src} [links]"),
        friction=friction,  # type: ignore[arg-type]  # _vec checked the length
        fingers=placements,
        motor=MotorConstants(
            stall_force_n=_num(motor, "stall_force_n", w),
            no_load_speed_m_s=_num(motor, "no_load_speed_m_s", w),
            moving_mass_kg=_num(motor, "moving_mass_kg", w),
            coulomb_friction_n=_num(motor, "coulomb_friction_n", w, bound="nonnegative"),
            viscous_friction_n_s_m=_num(motor, "viscous_friction_n_s_m", w, bound="nonnegative"),
            stroke_m=stroke,  # type: ignore[arg-type]  # _vec checked the length
            peak_force_n=_num(motor, "peak_force_n", w),
        ),
        pulley_radius_m=_num(rotary, "pulley_radius_m", f"{src} [rotary]"),
        dynamics=Dynamics(
            timestep_s=_num(dyn, "timestep_s", d),
            integrator=str(integrator),
            gravity_m_s2=_num(dyn, "gravity_m_s2", d),
            joint_damping_n_m_s=_num(dyn, "joint_damping_n_m_s", d, bound="nonnegative"),
            coupling_damping_n_s_m=_num(dyn, "coupling_damping_n_s_m", d),
        ),
        source=src,
    )
