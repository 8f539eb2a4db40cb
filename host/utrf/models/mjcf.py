"""The hand as a MuJoCo model (MJCF), generated from the geometry files.

Public API (kept stable for the emulator and for users):

- ``hand_xml(hand=None, layout=None, *, drive="duty") -> str``: the MJCF document.
- ``hand_model(hand=None, layout=None, *, drive="duty") -> mujoco.MjModel``.
- ``load_layout(path=None) -> Layout``: ``utrf/data/mjcf.toml`` (palm, finger placement,
  motors, contact, dynamics constants), errors naming the field (in ``mjcf_layout``).
- ``xml_numbers(*values) -> str``: numbers as an MJCF attribute (for writers of more MJCF).
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
Two fingers that flex in parallel planes further apart than their links' radii can never
touch (every joint is a hinge about its plane's normal): their pair is left out of the
affinities (:func:`never_touching`), which spares MuJoCo's collision search its checks and
changes no contact.

World frame: z up, the hand palm-up, fingers along +x, Joint-1 axes on the palm's top face
(z = 0). Gravity −z: for index..little it loads each finger along its −y, as on the paper's
bench. Every constant not in the geometry files is in ``utrf/data/mjcf.toml``, documented as
an assumption in docs/mujoco.md.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from typing import Any

import mujoco
import numpy as np

from utrf.models import tendons
from utrf.models.geometry import FingerGeometry, HandGeometry
from utrf.models.mjcf_layout import (
    INTEGRATORS,
    Dynamics,
    FingerPlacement,
    Layout,
    MjcfError,
    MotorConstants,
    load_layout,
)

FINGER_NAMES = ("thumb", "index", "middle", "ring", "little")
DRIVES = ("duty", "force")
FINGER_CONTYPE = 1  # finger i: FINGER_CONTYPE << i
_FINGER_BITS = 0b11111
PALM_CONTYPE = 1 << 5
OBJECT_CONTYPE = 1 << 6
OBJECT_CONAFFINITY = _FINGER_BITS | PALM_CONTYPE | OBJECT_CONTYPE
_SLACK_M = -10.0  # lower end of a tendon's dead band: slack at any negative stretch


# -- XML ----------------------------------------------------------------------------------------
def _num_text(v: float) -> str:
    text = repr(float(v))  # the shortest text that reads back as the same double
    return text[:-2] if text.endswith(".0") else text


def xml_numbers(*values: float) -> str:
    """Numbers as an MJCF attribute: space-separated, each the shortest text of its double."""
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
    apart: int = 0,
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
    conaffinity = (_FINGER_BITS & ~contype & ~apart) | OBJECT_CONTYPE
    dyn = layout.dynamics
    _sub(
        world_palm,
        "site",
        name=f"{name}_frame",
        pos=xml_numbers(*place.position_m),
        quat=xml_numbers(*quat),
        size="0.003",
        rgba="0.2 0.6 0.2 0.5",
        group="4",
    )
    parent = world_palm
    for k in range(3):
        radius = layout.link_radius_fraction * R[k]
        attrs: dict[str, Any] = {"name": f"{name}_link{k + 1}"}
        if k == 0:
            attrs.update(pos=xml_numbers(*place.position_m), quat=xml_numbers(*quat))
        else:
            attrs.update(pos=xml_numbers(L[k - 1], 0.0, 0.0))
        body = _sub(parent, "body", **attrs)
        m = geom.link_masses_kg[k]
        _sub(
            body,
            "inertial",
            pos=xml_numbers(geom.link_com_fraction[k] * L[k], 0.0, 0.0),
            mass=xml_numbers(m),
            diaginertia=xml_numbers(*_link_inertia(m, L[k], radius)),
        )
        _sub(
            body,
            "joint",
            name=f"{name}_j{k + 1}",
            type="hinge",
            axis="0 0 1",
            range=xml_numbers(*ranges[k]),
            solreflimit=xml_numbers(2.0 * dyn.timestep_s, 1.0),
            damping=xml_numbers(dyn.joint_damping_n_m_s),
        )
        # Link 3's capsule ends at the fingertip; the others reach the next joint.
        end = L[k] - radius if k == 2 else L[k]
        _sub(
            body,
            "geom",
            name=f"{name}_link{k + 1}",
            type="capsule",
            fromto=xml_numbers(0, 0, 0, max(end, 1e-4), 0, 0),
            size=xml_numbers(radius),
            mass="0",
            contype=contype,
            conaffinity=conaffinity,
            friction=xml_numbers(*layout.friction),
            rgba="0.75 0.78 0.82 1" if k % 2 == 0 else "0.62 0.66 0.72 1",
        )
        if k == 2:
            _sub(
                body,
                "site",
                name=f"{name}_tip",
                pos=xml_numbers(L[2], 0.0, 0.0),
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
                pos=xml_numbers(-0.5 * layout.palm_size_m[0], y, -0.5 * layout.palm_size_m[2]),
            )
            _sub(
                body,
                "joint",
                name=joint,
                type="slide",
                axis="1 0 0",
                range=xml_numbers(*mot.stroke_m),
                solreflimit=xml_numbers(2.0 * dyn.timestep_s, 1.0),
                damping=xml_numbers(mot.viscous_friction_n_s_m),
                frictionloss=xml_numbers(mot.coulomb_friction_n),
            )
            m = mot.moving_mass_kg
            _sub(
                body,
                "inertial",
                pos="0 0 0",
                mass=xml_numbers(m),
                diaginertia=xml_numbers(1e-6, 1e-6, 1e-6),
            )
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
            pos=xml_numbers(-0.5 * layout.palm_size_m[0], p[1], -0.5 * layout.palm_size_m[2]),
        )
        _sub(
            body,
            "joint",
            name=joint,
            type="hinge",
            axis="0 1 0",
            range=xml_numbers(mot.stroke_m[0] / r, mot.stroke_m[1] / r),
            solreflimit=xml_numbers(2.0 * dyn.timestep_s, 1.0),
            damping=xml_numbers(mot.viscous_friction_n_s_m * r * r),
            frictionloss=xml_numbers(mot.coulomb_friction_n * r),
        )
        inertia = mot.moving_mass_kg * r * r  # the moving mass at the pulley's rim
        _sub(
            body,
            "inertial",
            pos="0 0 0",
            mass=xml_numbers(mot.moving_mass_kg),
            diaginertia=xml_numbers(inertia / 2, inertia, inertia / 2),
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
            stiffness=xml_numbers(k),
            springlength=xml_numbers(_SLACK_M, 0.0),
            damping=xml_numbers(c),
        )
        for joint_name, coef in coefs:
            _sub(t, "joint", joint=joint_name, coef=xml_numbers(coef))


def _actuator(
    root: ET.Element, name: str, joint: str, gear: float, mot: MotorConstants, drive: str
) -> None:
    f, peak = mot.stall_force_n, mot.peak_force_n
    if drive == "duty":
        # DC motor at duty u: F = F_stall (u − v / v0); v is the actuator's (rim) speed. Driven
        # against its motion it brakes with more than F_stall, up to the driver's peak current
        # (clipped at F_stall, a finger at its stop made the carriage chatter, undamped on
        # every backward swing).
        _sub(
            root,
            "general",
            name=name,
            joint=joint,
            gear=xml_numbers(gear),
            ctrlrange="-1 1",
            forcerange=xml_numbers(-peak, peak),
            gainprm=xml_numbers(f),
            biastype="affine",
            biasprm=xml_numbers(0.0, 0.0, -f / mot.no_load_speed_m_s),
        )
    else:
        _sub(
            root,
            "motor",
            name=name,
            joint=joint,
            gear=xml_numbers(gear),
            ctrlrange=xml_numbers(-f, f),
            forcerange=xml_numbers(-peak, peak),
        )


def never_touching(hand: HandGeometry, layout: Layout) -> list[int]:
    """Per finger, the bits (``FINGER_CONTYPE << j``) of the fingers it can never touch: both
    flex in parallel planes (a finger's joints are hinges about its frame's z) whose distance
    is more than the sum of their thickest links' radii."""
    planes = []
    for spec in hand.fingers:
        place = layout.fingers[spec.name]
        normal = place.rotation()[:, 2]
        radius = layout.link_radius_fraction * max(spec.geometry.guide_radii_m)
        planes.append((normal, float(normal @ np.asarray(place.position_m)), radius))
    apart = [0] * len(planes)
    for i, (ni, di, ri) in enumerate(planes):
        for j, (nj, dj, rj) in enumerate(planes):
            sign = float(ni @ nj)
            parallel = i != j and abs(abs(sign) - 1.0) < 1e-9
            if parallel and abs(di - math.copysign(1.0, sign) * dj) > ri + rj:
                apart[i] |= FINGER_CONTYPE << j
    return apart


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
        timestep=xml_numbers(dyn.timestep_s),
        integrator=dyn.integrator,
        gravity=xml_numbers(0.0, 0.0, -dyn.gravity_m_s2),
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
        pos=xml_numbers(-lp / 2, 0.0, -tp / 2),
        size=xml_numbers(lp / 2, wp / 2, tp / 2),
        mass=xml_numbers(layout.palm_mass_kg),
        contype=PALM_CONTYPE,
        conaffinity=_FINGER_BITS | OBJECT_CONTYPE,
        friction=xml_numbers(*layout.friction),
        rgba="0.35 0.38 0.45 1",
    )
    # The palm is welded to the world, so MuJoCo's parent-child filter does not apply to it.
    contact = _sub(root, "contact")
    for spec in hand.fingers:
        _sub(contact, "exclude", body1="palm", body2=f"{spec.name}_link1")
    tendon_root = ET.Element("tendon")
    actuator_root = ET.Element("actuator")
    apart = never_touching(hand, layout)
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
            apart[i],
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


__all__ = [
    "DRIVES",
    "FINGER_CONTYPE",
    "FINGER_NAMES",
    "INTEGRATORS",
    "OBJECT_CONAFFINITY",
    "OBJECT_CONTYPE",
    "PALM_CONTYPE",
    "Dynamics",
    "FingerPlacement",
    "Layout",
    "MjcfError",
    "MotorConstants",
    "finger_frame",
    "hand_model",
    "hand_xml",
    "joint_ranges_rad",
    "load_layout",
    "set_coupled_pose",
    "xml_numbers",
]
