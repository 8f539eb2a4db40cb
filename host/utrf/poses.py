"""The pose library: poses are data (TOML), resolved to per-finger Joint-2 targets.

A pose gives each finger a normalised flexion (0 straight, 1 at θ1's upper limit, negative
extends), with optional per-finger overrides as a Joint-2 angle or a tendon displacement, and
an optional grasp (GRASP mode with an effort limit; the object's weight for planning).
The built-in library is ``utrf/data/poses.toml``; users add files, later ones win by name.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from utrf.models import kinematics
from utrf.models.geometry import HandGeometry, package_data, read_toml

TargetKind = Literal["flexion", "theta2", "q"]
_OVERRIDE_KEYS: dict[str, tuple[TargetKind, float]] = {
    "theta2_rad": ("theta2", 1.0),
    "theta2_deg": ("theta2", math.pi / 180),
    "q_m": ("q", 1.0),
}


class PoseError(ValueError):
    """A pose that cannot be used, with the file, pose and field that are wrong."""


def user_pose_file() -> Path:
    """Where a user's own poses live: $UTRF_POSES, else ~/.config/utrf/poses.toml."""
    env = os.environ.get("UTRF_POSES")
    if env:
        return Path(env)
    config = Path(os.environ.get("XDG_CONFIG_HOME", Path.home() / ".config"))
    return config / "utrf" / "poses.toml"


@dataclass(frozen=True)
class FingerTarget:
    kind: TargetKind
    value: float  # flexion (1), Joint-2 angle (rad) or q (m)


@dataclass(frozen=True)
class Grasp:
    effort: float  # largest duty used to close, 0..1
    load_kg: float = 0.0  # the object's weight, for setpoint planning


@dataclass(frozen=True)
class Pose:
    name: str
    description: str
    targets: Mapping[str, FingerTarget]  # by finger name; every finger of the hand
    grasp: Grasp | None = None
    source: str = field(default="<dict>", compare=False)
    #: the move's duration (s) when none is asked for; None: the Hand's default (1 s)
    duration_s: float | None = None

    def q(self, hand: HandGeometry) -> np.ndarray:
        """Tendon displacement per finger (m), in board order."""
        out = np.empty(len(hand.fingers))
        for i, finger in enumerate(hand.fingers):
            t = self.targets.get(finger.name, FingerTarget("flexion", 0.0))
            g = finger.geometry
            if t.kind == "flexion":
                out[i] = float(kinematics.q_from_flexion(g, t.value))
            elif t.kind == "theta2":
                out[i] = float(kinematics.q_from_theta2(g, t.value))
            else:
                out[i] = t.value
            lo, hi = g.q_range_m
            if not lo - 1e-12 <= out[i] <= hi + 1e-12:
                raise PoseError(
                    f"{self.source}: pose {self.name!r}, finger {finger.name!r}: target "
                    f"q = {out[i] * 1e3:.2f} mm is outside the finger's range "
                    f"[{lo * 1e3:.2f}, {hi * 1e3:.2f}] mm (theta1 within its limits)"
                )
        return out

    def theta2(self, hand: HandGeometry) -> np.ndarray:
        """Joint-2 target per finger (rad), in board order: what the firmware controls."""
        q = self.q(hand)
        return np.array(
            [kinematics.theta2_from_q(f.geometry, q[i]) for i, f in enumerate(hand.fingers)]
        )


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise PoseError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def parse_pose(
    name: str, table: Mapping[str, Any], finger_names: Iterable[str], source: str
) -> Pose:
    names = list(finger_names)
    where = f"{source}: pose {name!r}"
    unknown = sorted(set(table) - {"description", "flexion", "override", "grasp", "duration_s"})
    if unknown:
        raise PoseError(f"{where}: unknown key(s) {unknown}")
    flexion = table.get("flexion", {})
    if not isinstance(flexion, Mapping):
        raise PoseError(f"{where}: flexion must be a table of finger = value")
    targets: dict[str, FingerTarget] = {n: FingerTarget("flexion", 0.0) for n in names}
    for finger, value in flexion.items():
        if finger not in names:
            raise PoseError(f"{where}: flexion names finger {finger!r}; fingers are {names}")
        f = _number(value, f"{where}: flexion.{finger}")
        if not -1.0 <= f <= 1.0:
            raise PoseError(f"{where}: flexion.{finger} = {f} is outside [-1, 1]")
        targets[finger] = FingerTarget("flexion", f)
    overrides = table.get("override", {})
    if not isinstance(overrides, Mapping):
        raise PoseError(f"{where}: override must be a table of finger tables")
    for finger, spec in overrides.items():
        if finger not in names:
            raise PoseError(f"{where}: override names finger {finger!r}; fingers are {names}")
        single = isinstance(spec, Mapping) and len(spec) == 1
        if not (single and next(iter(spec)) in _OVERRIDE_KEYS):
            raise PoseError(
                f"{where}: override.{finger} must hold exactly one of {sorted(_OVERRIDE_KEYS)}"
            )
        key, value = next(iter(spec.items()))
        kind, scale = _OVERRIDE_KEYS[key]
        value_si = _number(value, f"{where}: override.{finger}.{key}") * scale
        targets[finger] = FingerTarget(kind, value_si)
    grasp = None
    if "grasp" in table:
        g = table["grasp"]
        if not isinstance(g, Mapping) or "effort" not in g:
            raise PoseError(f"{where}: grasp must be a table with effort (0..1)")
        effort = _number(g["effort"], f"{where}: grasp.effort")
        if not 0.0 < effort <= 1.0:
            raise PoseError(f"{where}: grasp.effort = {effort} is outside (0, 1]")
        load = _number(g.get("load_kg", 0.0), f"{where}: grasp.load_kg")
        if load < 0:
            raise PoseError(f"{where}: grasp.load_kg = {load} must be >= 0")
        grasp = Grasp(effort=effort, load_kg=load)
    duration = None
    if "duration_s" in table:
        duration = _number(table["duration_s"], f"{where}: duration_s")
        if not 0.0 < duration <= 60.0:
            raise PoseError(f"{where}: duration_s = {duration} is outside (0, 60] s")
    description = table.get("description", "")
    if not isinstance(description, str):
        raise PoseError(f"{where}: description must be a string")
    return Pose(
        name=name,
        description=description,
        targets=targets,
        grasp=grasp,
        source=source,
        duration_s=duration,
    )


class PoseLibrary(Mapping[str, Pose]):
    """Poses by name, in the order they were defined."""

    def __init__(self, poses: Iterable[Pose] = ()) -> None:
        self._poses: dict[str, Pose] = {}
        for p in poses:
            self._poses[p.name] = p

    def __getitem__(self, name: str) -> Pose:
        try:
            return self._poses[name]
        except KeyError:
            raise KeyError(f"no pose named {name!r}; poses are {sorted(self._poses)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._poses)

    def __len__(self) -> int:
        return len(self._poses)

    def add_file(self, path: str | Path, hand: HandGeometry) -> None:
        path = Path(path)
        doc = read_toml(path, "pose", PoseError)
        poses = doc.get("pose")
        if not isinstance(poses, Mapping):
            raise PoseError(f"{path}: needs [pose.NAME] tables")
        names = [f.name for f in hand.fingers]
        for name, table in poses.items():
            if not isinstance(table, Mapping):
                raise PoseError(f"{path}: pose {name!r} must be a table")
            pose = parse_pose(name, table, names, str(path))
            pose.q(hand)  # refuse unreachable targets at load time, not mid-motion
            self._poses[name] = pose

    @classmethod
    def load(
        cls,
        extra: Iterable[str | Path] = (),
        hand: HandGeometry | None = None,
        *,
        include_user: bool = True,
    ) -> PoseLibrary:
        """The built-in poses, then the user's file (if present), then ``extra`` files."""
        hand = hand or HandGeometry.default()
        lib = cls()
        with package_data("poses.toml") as builtin:
            lib.add_file(builtin, hand)
        user = user_pose_file()
        if include_user and user.exists():
            lib.add_file(user, hand)
        for path in extra:
            lib.add_file(path, hand)
        return lib
