"""The hand as a MuJoCo model (MJCF), generated from the geometry files.

Public API (kept stable for the emulator and for users):

- ``hand_xml(hand=None, layout=None, *, drive="duty") -> str``: the MJCF document.
- ``hand_model(hand=None, layout=None, *, drive="duty") -> mujoco.MjModel``.
- ``load_layout(path=None) -> Layout``: ``utrf/data/mjcf.toml`` (palm, finger placement,
  motors, contact, dynamics constants), errors naming the field.
- ``set_coupled_pose(model, data, q_by_finger, hand=None)``: put fingers at tendon
  displacements q (m) on the rigid coupling (θ_i = q / R_i), the motors where they hold them
  with every tendon just taut, velocities zero; runs ``mj_forward``.
- ``finger_frame(model, data, finger) -> (origin (3,), rotation (3, 3))``: the finger's model
  frame (``utrf.models.geometry``) in world coordinates; columns x (along the finger), y
  (flexion side), z (joint axes).
- Constants: ``FINGER_CONTYPE``, ``PALM_CONTYPE``, ``OBJECT_CONTYPE``, ``OBJECT_CONAFFINITY``
  (collision bits, see below), ``DRIVES``.

Names in the model, for finger ``f`` in thumb, index, middle, ring, little:

- bodies ``palm`` (fixed to the world), ``f_link1``, ``f_link2``, ``f_link3``; hinge joints
  ``f_j1``, ``f_j2``, ``f_j3`` (relative angles, positive in flexion, as in the models);
  site ``f_tip`` (the fingertip, L3 along Link 3) and site ``f_frame`` (on the palm, at Joint 1,
  oriented as the finger's frame);
- antagonistic finger: motor carriages ``f_motor_a`` / ``f_motor_b`` with slide joints ``f_xa``
  (pulls Tendon 1, flexion) and ``f_xb`` (pulls Tendon 4, extension), positive = pulling,
  0 = straight finger, range = the stroke; actuators ``f_motor_a``, ``f_motor_b``;
- rotary finger: a pulley ``f_pulley`` (hinge joint ``f_pulley``, positive flexes) winding
  both actuating tendons; actuator ``f_motor``;
- tendons ``f_t1`` .. ``f_t6`` (the paper's Tendons 1-6): MuJoCo fixed tendons whose length is
  the strand's stretch on the routing (0 = just taut):
  t1 = x_a − R1 θ1, t4 = x_b + R1 θ1, t2 = R1 θ1 − R2 θ2 = −t5, t3 = R2 θ2 − R3 θ3 = −t6.
  Each is a linear spring E A / L_T (Eq. 13-15) that pulls only when stretched (a dead band
  below zero stretch): tension-only. These length relations are the routing's (Eq. 2); spatial
  tendons wrapped on cylinders pick the wrong wrap side past 90° of a joint.

Actuators (``drive``): ``"duty"`` (default): ctrl in [−1, 1] is the H-bridge's averaged duty,
and the actuator is the DC motor at that voltage, F = F_stall (duty − v / v_no_load), limited
to ±F_stall: stall force, no-load speed and (joint range) stroke are its force, speed and
travel limits; at duty 0 it is a short brake. ``"force"``: ctrl is the motor force in N
(±F_stall), for a caller that models the motor's electrics itself (coasting, current limits).

Collisions: a finger's links collide with the other fingers, the palm and objects, not with
each other (the paper's model, like the real finger, ignores that). Bits: finger i has contype
``1 << i``; the palm ``PALM_CONTYPE``; objects ``OBJECT_CONTYPE`` with ``OBJECT_CONAFFINITY``.

World frame: z up, the hand palm-up, fingers along +x, Joint-1 axes on the palm's top face
(z = 0). Gravity −z: for index..little it loads each finger along its −y, as on the paper's
bench. Every constant not in the geometry files is in ``utrf/data/mjcf.toml``, documented as
an assumption in docs/mujoco.md.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from utrf.models import tendons
from utrf.models.geometry import FingerGeometry, HandGeometry, read_toml

FINGER_NAMES = ("thumb", "index", "middle", "ring", "little")
DRIVES = ("duty", "force")
INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")
FINGER_CONTYPE = 1  # finger i: FINGER_CONTYPE << i
_FINGER_BITS = 0b11111
PALM_CONTYPE = 1 << 5
OBJECT_CONTYPE = 1 << 6
OBJECT_CONAFFINITY = _FINGER_BITS | PALM_CONTYPE | OBJECT_CONTYPE
_SLACK_M = -10.0  # lower end of a tendon's dead band: slack at any negative stretch


class MjcfError(ValueError):
    """A layout or hand that cannot be turned into a MuJoCo model; the message names it."""


@dataclass(frozen=True)
class FingerPlacement:
    """Where a finger's Joint 1 sits on the palm and how its frame is turned."""

    position_m: tuple[float, float, float]
    yaw_rad: float
    roll_rad: float

    def rotation(self) -> np.ndarray:
        """Finger frame axes (columns x, y, z) in the palm frame."""
        cy, sy = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        cr, sr = math.cos(self.roll_rad), math.sin(self.roll_rad)
        yaw = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        # The finger's (x, y, z) at yaw = roll = 0 is (x, z, −y) of the palm: it flexes up.
        base = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
        roll = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        return yaw @ base @ roll

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
        ref = resources.files("utrf") / "data" / "mjcf.toml"
        with resources.as_file(ref) as p:
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


# -- XML ----------------------------------------------------------------------------------------
def _num_text(v: float) -> str:
    text = repr(float(v))  # the shortest text that reads back as the same double
    return text[:-2] if text.endswith(".0") else text


def _f(*values: float) -> str:
    return " ".join(_num_text(v) for v in values)


def _sub(parent: ET.Element, tag: str, **attrs: Any) -> ET.Element:
    return ET.SubElement(parent, tag, {k: str(v) for k, v in attrs.items()})


def joint_ranges_rad(geom: FingerGeometry) -> np.ndarray:
    """(3, 2) joint limits: θ1 its range; θ2, θ3 where a coupling strand would leave its guide
    (|θ2| ≤ min(α20, α30), |θ3| ≤ α30: ``utrf.models.tendons.wrap_angles``)."""
    a2, a3 = tendons.straight_wrap_angles(geom)
    return np.array(
        [list(geom.theta1_range_rad), [-min(a2, a3), min(a2, a3)], [-a3, a3]], dtype=float
    )


def _link_inertia(mass: float, length: float, radius: float) -> tuple[float, float, float]:
    # A uniform rod about its centre (the emulator's assumption), with a solid cylinder's
    # axial term so the inertia is a valid one.
    rod = mass * length**2 / 12.0
    return (mass * radius**2 / 2.0, rod, rod)


def _add_finger(
    world_palm: ET.Element,
    tendon_root: ET.Element,
    actuator_root: ET.Element,
    index: int,
    name: str,
    geom: FingerGeometry,
    actuation: str,
    place: FingerPlacement,
    layout: Layout,
    drive: str,
) -> None:
    L, R = geom.link_lengths_m, geom.guide_radii_m
    if min(geom.link_masses_kg) <= 0:
        raise MjcfError(
            f"{geom.source}: link_masses_kg must all be > 0 for MuJoCo, got "
            f"{list(geom.link_masses_kg)}"
        )
    quat = place.quat()
    ranges = joint_ranges_rad(geom)
    contype = FINGER_CONTYPE << index
    conaffinity = (_FINGER_BITS & ~contype) | OBJECT_CONTYPE
    dyn = layout.dynamics
    _sub(
        world_palm,
        "site",
        name=f"{name}_frame",
        pos=_f(*place.position_m),
        quat=_f(*quat),
        size="0.003",
        rgba="0.2 0.6 0.2 0.5",
        group="4",
    )
    parent = world_palm
    for k in range(3):
        radius = layout.link_radius_fraction * R[k]
        attrs: dict[str, Any] = {"name": f"{name}_link{k + 1}"}
        if k == 0:
            attrs.update(pos=_f(*place.position_m), quat=_f(*quat))
        else:
            attrs.update(pos=_f(L[k - 1], 0.0, 0.0))
        body = _sub(parent, "body", **attrs)
        m = geom.link_masses_kg[k]
        _sub(
            body,
            "inertial",
            pos=_f(geom.link_com_fraction[k] * L[k], 0.0, 0.0),
            mass=_f(m),
            diaginertia=_f(*_link_inertia(m, L[k], radius)),
        )
        _sub(
            body,
            "joint",
            name=f"{name}_j{k + 1}",
            type="hinge",
            axis="0 0 1",
            range=_f(*ranges[k]),
            solreflimit=_f(2.0 * dyn.timestep_s, 1.0),
            damping=_f(dyn.joint_damping_n_m_s),
        )
        # Link 3's capsule ends at the fingertip; the others reach the next joint.
        end = L[k] - radius if k == 2 else L[k]
        _sub(
            body,
            "geom",
            name=f"{name}_link{k + 1}",
            type="capsule",
            fromto=_f(0, 0, 0, max(end, 1e-4), 0, 0),
            size=_f(radius),
            mass="0",
            contype=contype,
            conaffinity=conaffinity,
            friction=_f(*layout.friction),
            rgba="0.75 0.78 0.82 1" if k % 2 == 0 else "0.62 0.66 0.72 1",
        )
        if k == 2:
            _sub(
                body,
                "site",
                name=f"{name}_tip",
                pos=_f(L[2], 0.0, 0.0),
                size="0.004",
                rgba="0.85 0.2 0.2 1",
            )
        parent = body

    # Motors: carriages (or the pulley) inside the palm, not colliding, hidden (group 3).
    mot = layout.motor
    p = np.asarray(place.position_m)
    # The moving mass is the body's own, not joint armature: MuJoCo scales a joint limit's
    # softness by the body inertia it sees at qpos0, and with the mass in armature a 100 N
    # motor runs through the end of its stroke.
    carriage = {
        "type": "sphere",
        "size": "0.004",
        "mass": "0",
        "contype": "0",
        "conaffinity": "0",
        "group": "3",
        "rgba": "0.9 0.6 0.1 1",
    }
    stiff = tendons.stiffnesses(geom)
    if actuation == "antagonistic":
        coef_motor = {1: (f"{name}_xa", 1.0), 4: (f"{name}_xb", 1.0)}
        for side, joint in (("a", f"{name}_xa"), ("b", f"{name}_xb")):
            y = p[1] + (-0.004 if side == "a" else 0.004)
            body = _sub(
                world_palm,
                "body",
                name=f"{name}_motor_{side}",
                pos=_f(-0.5 * layout.palm_size_m[0], y, -0.5 * layout.palm_size_m[2]),
            )
            _sub(
                body,
                "joint",
                name=joint,
                type="slide",
                axis="1 0 0",
                range=_f(*mot.stroke_m),
                solreflimit=_f(2.0 * dyn.timestep_s, 1.0),
                damping=_f(mot.viscous_friction_n_s_m),
                frictionloss=_f(mot.coulomb_friction_n),
            )
            m = mot.moving_mass_kg
            _sub(body, "inertial", pos="0 0 0", mass=_f(m), diaginertia=_f(1e-6, 1e-6, 1e-6))
            _sub(body, "geom", **carriage)
            _actuator(actuator_root, f"{name}_motor_{side}", joint, 1.0, mot, drive)
    else:
        r = layout.pulley_radius_m
        joint = f"{name}_pulley"
        coef_motor = {1: (joint, r), 4: (joint, -r)}
        body = _sub(
            world_palm,
            "body",
            name=joint,
            pos=_f(-0.5 * layout.palm_size_m[0], p[1], -0.5 * layout.palm_size_m[2]),
        )
        _sub(
            body,
            "joint",
            name=joint,
            type="hinge",
            axis="0 1 0",
            range=_f(mot.stroke_m[0] / r, mot.stroke_m[1] / r),
            solreflimit=_f(2.0 * dyn.timestep_s, 1.0),
            damping=_f(mot.viscous_friction_n_s_m * r * r),
            frictionloss=_f(mot.coulomb_friction_n * r),
        )
        inertia = mot.moving_mass_kg * r * r  # the moving mass at the pulley's rim
        _sub(
            body,
            "inertial",
            pos="0 0 0",
            mass=_f(mot.moving_mass_kg),
            diaginertia=_f(inertia / 2, inertia, inertia / 2),
        )
        _sub(body, "geom", **carriage)
        _actuator(actuator_root, f"{name}_motor", joint, r, mot, drive)

    j = [f"{name}_j1", f"{name}_j2", f"{name}_j3"]
    # (tendon, [(joint, coef)], stiffness, damping): stretch = Σ coef · qpos.
    spec = [
        (1, [coef_motor[1], (j[0], -R[0])], stiff[0], 0.0),
        (4, [coef_motor[4], (j[0], R[0])], stiff[0], 0.0),
        (2, [(j[0], R[0]), (j[1], -R[1])], stiff[1], 0.5 * dyn.coupling_damping_n_s_m),
        (5, [(j[0], -R[0]), (j[1], R[1])], stiff[1], 0.5 * dyn.coupling_damping_n_s_m),
        (3, [(j[1], R[1]), (j[2], -R[2])], stiff[2], 0.5 * dyn.coupling_damping_n_s_m),
        (6, [(j[1], -R[1]), (j[2], R[2])], stiff[2], 0.5 * dyn.coupling_damping_n_s_m),
    ]
    for number, coefs, k, c in sorted(spec):
        t = _sub(
            tendon_root,
            "fixed",
            name=f"{name}_t{number}",
            stiffness=_f(k),
            springlength=_f(_SLACK_M, 0.0),
            damping=_f(c),
        )
        for joint_name, coef in coefs:
            _sub(t, "joint", joint=joint_name, coef=_f(coef))


def _actuator(
    root: ET.Element, name: str, joint: str, gear: float, mot: MotorConstants, drive: str
) -> None:
    f = mot.stall_force_n
    if drive == "duty":
        # DC motor at duty u: F = F_stall (u − v / v0); v is the actuator's (rim) speed.
        _sub(
            root,
            "general",
            name=name,
            joint=joint,
            gear=_f(gear),
            ctrlrange="-1 1",
            forcerange=_f(-f, f),
            gainprm=_f(f),
            biastype="affine",
            biasprm=_f(0.0, 0.0, -f / mot.no_load_speed_m_s),
        )
    else:
        _sub(
            root,
            "motor",
            name=name,
            joint=joint,
            gear=_f(gear),
            ctrlrange=_f(-f, f),
            forcerange=_f(-f, f),
        )


def hand_xml(
    hand: HandGeometry | None = None,
    layout: Layout | None = None,
    *,
    drive: str = "duty",
) -> str:
    """The MJCF of the hand (default: the package's hand.toml and mjcf.toml)."""
    hand = hand if hand is not None else HandGeometry.default()
    layout = layout if layout is not None else load_layout()
    if drive not in DRIVES:
        raise MjcfError(f"drive must be one of {DRIVES}, got {drive!r}")
    names = [f.name for f in hand.fingers]
    if sorted(names) != sorted(FINGER_NAMES):
        raise MjcfError(f"the hand's fingers must be {list(FINGER_NAMES)}, got {names}")
    missing = [n for n in names if n not in layout.fingers]
    if missing:
        raise MjcfError(f"{layout.source}: no [fingers.NAME] placement for {missing}")
    dyn = layout.dynamics
    root = ET.Element("mujoco", model=hand.name)
    _sub(root, "compiler", angle="radian", autolimits="true")
    _sub(
        root,
        "option",
        timestep=_f(dyn.timestep_s),
        integrator=dyn.integrator,
        gravity=_f(0.0, 0.0, -dyn.gravity_m_s2),
    )
    visual = _sub(root, "visual")
    _sub(visual, "global", offwidth="1280", offheight="960")
    _sub(visual, "headlight", ambient="0.35 0.35 0.35", diffuse="0.5 0.5 0.5")
    asset = _sub(root, "asset")
    _sub(
        asset,
        "texture",
        type="skybox",
        builtin="gradient",
        rgb1="0.92 0.94 0.97",
        rgb2="0.55 0.6 0.68",
        width="64",
        height="64",
    )
    world = _sub(root, "worldbody")
    _sub(world, "light", name="key", pos="0.1 -0.3 0.5", dir="-0.2 0.5 -1", diffuse="0.6 0.6 0.6")
    palm = _sub(world, "body", name="palm")
    lp, wp, tp = layout.palm_size_m
    _sub(
        palm,
        "geom",
        name="palm",
        type="box",
        pos=_f(-lp / 2, 0.0, -tp / 2),
        size=_f(lp / 2, wp / 2, tp / 2),
        mass=_f(layout.palm_mass_kg),
        contype=PALM_CONTYPE,
        conaffinity=_FINGER_BITS | OBJECT_CONTYPE,
        friction=_f(*layout.friction),
        rgba="0.35 0.38 0.45 1",
    )
    # The palm is welded to the world, so MuJoCo's parent-child filter does not apply to it.
    contact = _sub(root, "contact")
    for spec in hand.fingers:
        _sub(contact, "exclude", body1="palm", body2=f"{spec.name}_link1")
    tendon_root = ET.Element("tendon")
    actuator_root = ET.Element("actuator")
    for i, spec in enumerate(hand.fingers):
        _add_finger(
            palm,
            tendon_root,
            actuator_root,
            i,
            spec.name,
            spec.geometry,
            spec.actuation,
            layout.fingers[spec.name],
            layout,
            drive,
        )
    root.append(tendon_root)
    root.append(actuator_root)
    ET.indent(root)
    header = (
        f"<!-- {hand.name} for MuJoCo, generated by utrf.models.mjcf (utrf mjcf) from the "
        "geometry files and data/mjcf.toml; do not edit by hand. -->\n"
    )
    return header + ET.tostring(root, encoding="unicode") + "\n"


def hand_model(
    hand: HandGeometry | None = None,
    layout: Layout | None = None,
    *,
    drive: str = "duty",
) -> mujoco.MjModel:
    """The compiled hand model."""
    return mujoco.MjModel.from_xml_string(hand_xml(hand, layout, drive=drive))


# -- helpers on a compiled model ------------------------------------------------------------------
def _qadr(model: mujoco.MjModel, joint: str) -> int:
    return int(model.jnt_qposadr[model.joint(joint).id])


def set_coupled_pose(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    q_by_finger: Mapping[str, float],
    hand: HandGeometry | None = None,
) -> None:
    """Fingers at tendon displacements q (m) on the rigid coupling, motors where every tendon
    is just taut (x_a = q, x_b = −q; a pulley at q / r), velocities zero; then ``mj_forward``.
    The motors' positions are read from the model's actuating tendons (Tendons 1 and 4)."""
    hand = hand if hand is not None else HandGeometry.default()
    for name, q in q_by_finger.items():
        R = hand.fingers[hand.index(name)].geometry.guide_radii_m
        for k in range(3):
            data.qpos[_qadr(model, f"{name}_j{k + 1}")] = q / R[k]
        # The motor is each actuating tendon's first joint: stretch 0 at coef · x = ±q.
        for tendon, sign in (("t1", 1.0), ("t4", -1.0)):
            t = model.tendon(f"{name}_{tendon}").id
            adr = int(model.tendon_adr[t])
            joint, coef = int(model.wrap_objid[adr]), float(model.wrap_prm[adr])
            data.qpos[model.jnt_qposadr[joint]] = sign * q / coef
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)


def finger_frame(
    model: mujoco.MjModel, data: mujoco.MjData, finger: str
) -> tuple[np.ndarray, np.ndarray]:
    """The finger's model frame in world coordinates: origin (Joint 1) and rotation (3, 3)."""
    site = data.site(f"{finger}_frame")
    return site.xpos.copy(), site.xmat.reshape(3, 3).copy()
