"""Objects for the MuJoCo hand to grasp, as data (``utrf/data/objects.toml``).

- ``load_objects(path=None) -> dict[str, GraspObject]``: the library, errors naming the file,
  object and field (:class:`ObjectError`).
- ``get_object(name, path=None) -> GraspObject``.
- ``add_object(xml, obj, position_m, quat=(1, 0, 0, 0), *, name=None) -> str``: the hand's
  MJCF (``utrf.models.mjcf.hand_xml``) with the object added as a free body at that pose
  (world frame). In the model: body ``NAME``, free joint ``NAME_free``, geom ``NAME``; its
  friction takes precedence over the hand's on its contacts (``priority``), and it collides
  with the fingers, the palm and other objects.

Each object also says how the emulated grasp hold takes it (``grasp_pose``, ``grasp_effort``,
``grasp_thumb``: whether the thumb closes on it too; ``rest_position_m`` and ``rest_axis``:
where it rests on the palm-up hand).
A fragile object has a ``breaking_force_n``: the largest contact force it survives (the
simulation reports breakage; MuJoCo does not break it).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from utrf.models import mjcf
from utrf.models.geometry import package_data, read_toml

SHAPES = {"sphere": 1, "cylinder": 2, "box": 3, "ellipsoid": 3}  # number of sizes
_KEYS = {
    "description",
    "shape",
    "size_m",
    "mass_kg",
    "friction",
    "breaking_force_n",
    "grasp_pose",
    "grasp_effort",
    "grasp_thumb",
    "rest_position_m",
    "rest_axis",
}
#: the unit quaternion (w, x, y, z) that turns an object's own z axis onto a world axis
AXIS_QUAT = {
    "z": (1.0, 0.0, 0.0, 0.0),
    "y": (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0),
    "x": (math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0),
}
# Torsional and rolling friction with the object's sliding one (MuJoCo's defaults' scale).
_TORSION_M, _ROLLING_M = 0.005, 0.0001


class ObjectError(ValueError):
    """An object description that cannot be used; the message names the file and field."""


@dataclass(frozen=True)
class GraspObject:
    name: str
    description: str
    shape: str
    size_m: tuple[float, ...]
    mass_kg: float
    friction: float
    breaking_force_n: float | None = None  # None: not fragile
    grasp_pose: str | None = None  # the pose library's grasp that holds it
    grasp_effort: float | None = None  # None: the pose's own
    grasp_thumb: bool = False  # the thumb closes on it too (else the four fingers cage it)
    rest_position_m: tuple[float, float, float] | None = None  # on the palm-up hand, world
    rest_axis: str = "z"  # the world axis its own z axis points along there

    @property
    def fragile(self) -> bool:
        return self.breaking_force_n is not None

    @property
    def rest_quat(self) -> tuple[float, float, float, float]:
        """Its orientation resting on the palm (w, x, y, z), world frame."""
        return AXIS_QUAT[self.rest_axis]


def _positive(table: Mapping[str, Any], key: str, where: str) -> float:
    v = table.get(key)
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
        raise ObjectError(f"{where}: {key} must be a number > 0, got {v!r}")
    return float(v)


def parse_object(name: str, table: Mapping[str, Any], source: str = "<dict>") -> GraspObject:
    where = f"{source} [object.{name}]"
    unknown = sorted(set(table) - _KEYS)
    if unknown:
        raise ObjectError(f"{where}: unknown key(s) {unknown}; expected {sorted(_KEYS)}")
    shape = table.get("shape")
    if shape not in SHAPES:
        raise ObjectError(f"{where}: shape must be one of {sorted(SHAPES)}, got {shape!r}")
    size = table.get("size_m")
    if (
        not isinstance(size, Sequence)
        or isinstance(size, str)
        or len(size) != SHAPES[shape]
        or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0
            for v in size
        )
    ):
        raise ObjectError(
            f"{where}: size_m of a {shape} must be {SHAPES[shape]} number(s) > 0, got {size!r}"
        )
    breaking = table.get("breaking_force_n")
    pose = table.get("grasp_pose")
    if pose is not None and not (isinstance(pose, str) and pose):
        raise ObjectError(f"{where}: grasp_pose must be a pose name, got {pose!r}")
    effort = table.get("grasp_effort")
    if effort is not None and not (
        isinstance(effort, int | float) and not isinstance(effort, bool) and 0 < effort <= 1
    ):
        raise ObjectError(f"{where}: grasp_effort must lie in (0, 1], got {effort!r}")
    thumb = table.get("grasp_thumb", False)
    if not isinstance(thumb, bool):
        raise ObjectError(f"{where}: grasp_thumb must be true or false, got {thumb!r}")
    rest = table.get("rest_position_m")
    if rest is not None:
        rest = _vector(rest, 3, f"{where}: rest_position_m")
    axis = table.get("rest_axis", "z")
    if axis not in AXIS_QUAT:
        raise ObjectError(f"{where}: rest_axis must be one of {sorted(AXIS_QUAT)}, got {axis!r}")
    return GraspObject(
        name=name,
        description=str(table.get("description", "")),
        shape=shape,
        size_m=tuple(float(v) for v in size),
        mass_kg=_positive(table, "mass_kg", where),
        friction=_positive(table, "friction", where),
        breaking_force_n=None if breaking is None else _positive(table, "breaking_force_n", where),
        grasp_pose=pose,
        grasp_effort=None if effort is None else float(effort),
        grasp_thumb=thumb,
        rest_position_m=None if rest is None else (rest[0], rest[1], rest[2]),
        rest_axis=str(axis),
    )


def load_objects(path: str | Path | None = None) -> dict[str, GraspObject]:
    """The object library (default: the package's ``data/objects.toml``)."""
    if path is None:
        with package_data("objects.toml") as p:
            return load_objects(p)
    path = Path(path)
    doc = read_toml(path, "object", ObjectError)
    objects = doc.get("object")
    if not isinstance(objects, Mapping) or not objects:
        raise ObjectError(f"{path}: needs [object.NAME] tables")
    out = {}
    for name, table in objects.items():
        if not isinstance(table, Mapping):
            raise ObjectError(f"{path}: object {name!r} must be a table")
        out[name] = parse_object(name, table, str(path))
    return out


def get_object(name: str, path: str | Path | None = None) -> GraspObject:
    library = load_objects(path)
    try:
        return library[name]
    except KeyError:
        raise ObjectError(f"no object named {name!r}; objects are {sorted(library)}") from None


def _vector(value: Sequence[float], n: int, what: str) -> tuple[float, ...]:
    if isinstance(value, str | bytes):
        raise ObjectError(f"{what} must be {n} finite numbers, got {value!r}")
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise ObjectError(f"{what} must be {n} finite numbers, got {value!r}") from None
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise ObjectError(f"{what} must be {n} finite numbers, got {value!r}")
    return v


def add_object(
    xml: str,
    obj: GraspObject | str,
    position_m: Sequence[float],
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    *,
    name: str | None = None,
) -> str:
    """``xml`` (an MJCF document) with ``obj`` added as a free body at ``position_m``, turned by
    the unit quaternion ``quat`` (w, x, y, z), both in the world frame."""
    if isinstance(obj, str):
        obj = get_object(obj)
    pos = _vector(position_m, 3, "position_m")
    q = _vector(quat, 4, "quat")
    norm = math.sqrt(sum(c * c for c in q))
    if not abs(norm - 1.0) < 1e-6:
        raise ObjectError(f"quat must be a unit quaternion (w, x, y, z), got {tuple(quat)}")
    name = name or obj.name
    header, sep, body = xml.partition("<mujoco")
    root = ET.fromstring(sep + body)
    world = root.find("worldbody")
    if world is None:
        raise ObjectError("the MJCF has no <worldbody>")
    if any(e.get("name") in (name, f"{name}_free") for e in root.iter()):
        raise ObjectError(f"the MJCF already has an element named {name!r}")
    f = mjcf.xml_numbers
    b = ET.SubElement(world, "body", name=name, pos=f(*pos), quat=f(*q))
    ET.SubElement(b, "freejoint", name=f"{name}_free")
    ET.SubElement(
        b,
        "geom",
        name=name,
        type=obj.shape,
        size=f(*obj.size_m),
        mass=f(obj.mass_kg),
        friction=f(obj.friction, _TORSION_M, _ROLLING_M),
        priority="1",
        condim="4",
        contype=str(mjcf.OBJECT_CONTYPE),
        conaffinity=str(mjcf.OBJECT_CONAFFINITY),
        rgba="0.95 0.85 0.6 1" if obj.fragile else "0.3 0.55 0.85 1",
    )
    ET.indent(root)
    return header + ET.tostring(root, encoding="unicode") + "\n"
