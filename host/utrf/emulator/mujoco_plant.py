"""The MuJoCo hand as the emulated board's plant (``EmulatedBoard(plant="mujoco")``).

The model is :func:`utrf.models.mjcf.hand_xml` with ``drive="force"`` (each actuator's
control is its motor's force, N), optionally with an object of :mod:`utrf.models.objects`.
The mujoco package owns the ``MjModel`` and ``MjData``; the harness (``harness/mjplant.c``)
steps them in C in lockstep with the MCU, as many ``mj_step`` per exchange as the MJCF's
timestep (0.5 ms) fits in the board's exchange period (1 ms: two): the TB6612FNG truth
table and the DC motor's electrical model (:class:`~utrf.emulator.plant_params.MotorParams`) turn
the firmware's pins into the actuators' forces, and Joint 2's angle becomes the AS5600's
analog voltage
(:class:`~utrf.emulator.plant_params.EncoderParams`: 12-bit, 10-90 % band, seeded noise). Everything
MuJoCo knows (poses, contacts, the object) is live in :attr:`MujocoPlant.data`.

Gravity is the model's, −z in the world (for index..little, −y of the finger frame, as on the
bench); ``PlantParams.gravity_m_s2 == (0, 0)`` turns it off. The coupling tendons are
elastic (stiffness from E, A and each segment's length): their modulus is the geometry's, or
``PlantParams.coupling_modulus_pa`` (the emulated truth's hidden modulus, :func:`twin_geometry`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import mujoco
import numpy as np

from utrf.emulator._native import HarnessError, MjPlantParamsC, NativeMjPlant, _NativeStepper
from utrf.emulator.plant_params import (
    FINGERS,
    EncoderParams,
    PlantError,
    PlantParams,
    _finger_index,
    _force_vector,
)
from utrf.models import mjcf, objects
from utrf.models.geometry import HandGeometry

IMPRATIO = 10.0


def twin_geometry(hand: HandGeometry, params: PlantParams) -> HandGeometry:
    """The hand the twin is built from: the model's, with the coupling tendons' modulus of
    ``params.coupling_modulus_pa`` where one is given (a hidden truth the model does not know:
    stiffer or softer tendons stretch less or more under a tip load)."""
    modulus = params.coupling_modulus_pa
    if modulus is None:
        return hand
    fingers = tuple(
        dataclasses.replace(
            f, geometry=dataclasses.replace(f.geometry, tendon_youngs_modulus_pa=modulus)
        )
        for f in hand.fingers
    )
    return dataclasses.replace(hand, fingers=fingers)


def twin_layout(params: PlantParams) -> mjcf.Layout:
    """The MJCF layout with the plant's motors (``params.motor``: the hand's, or the static
    loading bench's stronger actuator), so the model's force limits, speeds and friction are
    the ones the motor model drives."""
    mot = params.motor
    motor = mjcf.MotorConstants(
        stall_force_n=mot.stall_force_n,
        no_load_speed_m_s=mot.no_load_speed_m_s,
        moving_mass_kg=mot.moving_mass_kg,
        coulomb_friction_n=mot.coulomb_friction_n,
        viscous_friction_n_s_m=mot.viscous_friction_n_s_m,
        stroke_m=(float(mot.stroke_m[0]), float(mot.stroke_m[1])),
        peak_force_n=mot.peak_force_n,
    )
    return dataclasses.replace(mjcf.load_layout(), motor=motor)


def libmujoco_path() -> str:
    """The libmujoco the mujoco package loaded (the harness steps with it)."""
    root = Path(mujoco.__file__).resolve().parent
    found = sorted(root.glob("libmujoco.so*"))
    if not found:
        raise HarnessError(f"no libmujoco.so* next to the mujoco package in {root}")
    return str(found[-1])


def _put_encoder(c: MjPlantParamsC, e: EncoderParams) -> None:
    """The encoder's constants into the C plant's parameters (its ``enc_*`` fields)."""
    c.enc_supply, c.enc_offset = e.supply_v, e.offset_rad
    np.ctypeslib.as_array(c.enc_band)[...] = e.band
    c.enc_noise_v, c.enc_unplugged_v = e.noise_v, e.unplugged_v
    c.enc_invert, c.enc_bits = int(e.invert), e.resolution_bits


class _FingerPlant:
    """The plant's checks and encoder faults: the hand it takes, the range check on a Joint-2
    angle, and the encoder's unplugged, replugged and slipped states (kept apart from
    :class:`MujocoPlant`, which is long enough on its own)."""

    hand: HandGeometry
    params: PlantParams
    R: np.ndarray
    q_limits: np.ndarray
    encoder_shift: np.ndarray
    _st: dict[str, np.ndarray]
    _native: _NativeStepper

    @property
    def time(self) -> float:
        return self._native.time

    @property
    def drive_mode(self) -> np.ndarray:
        """Per finger and motor: 0 coast, 1 brake, 2 forward, 3 reverse."""
        return self._st["drive_mode"].astype(np.int8)

    def encoder_volts(self) -> np.ndarray:
        """Each finger's AS5600 output (V), noise included: the ADC0..4 inputs."""
        return self._native.encoder_volts()

    def _take_hand(self, hand: HandGeometry | None, params: PlantParams | None) -> None:
        self.hand = hand if hand is not None else HandGeometry.default()
        if len(self.hand.fingers) != FINGERS:
            raise PlantError(
                f"the plant needs {FINGERS} fingers, the hand has {len(self.hand.fingers)}"
            )
        self.params = params if params is not None else PlantParams()
        self.geometries = tuple(f.geometry for f in self.hand.fingers)

    def _q_at_theta2(self, f: int, theta2: float) -> float:
        """Joint-2 angle ``theta2`` (rad) of finger ``f`` as its q (m), inside its range."""
        q = float(theta2) * self.R[f, 1]
        lo, hi = self.q_limits[f]
        if not lo <= q <= hi:
            raise PlantError(
                f"finger {f}: θ2 = {theta2:.3f} rad is outside its range "
                f"[{lo / self.R[f, 1]:.3f}, {hi / self.R[f, 1]:.3f}] rad"
            )
        return q

    @staticmethod
    def _check_direction(direction: str) -> None:
        if direction not in ("both", "flexion"):
            raise PlantError(f"direction must be 'both' or 'flexion', got {direction!r}")

    def unplug_encoder(self, finger: int, volts: float | None = None) -> None:
        """The encoder's cable comes off: the ADC input reads ``volts`` (default: the
        encoder parameters' ``unplugged_v``, 0 V)."""
        f = _finger_index(finger)
        if volts is None:
            volts = self.params.encoder.unplugged_v
        if not (math.isfinite(volts) and 0.0 <= volts <= 5.0):
            raise PlantError(f"an unplugged encoder's input must lie in [0, 5] V, got {volts!r}")
        self._st["unplugged_v"][f] = volts
        self._st["plugged"][f] = 0.0

    def plug_encoder(self, finger: int) -> None:
        self._st["plugged"][_finger_index(finger)] = 1.0

    def shift_encoder(self, finger: int, radians: float) -> None:
        """The encoder's magnet slips: its reading is off by ``radians`` from now on."""
        f = _finger_index(finger)
        if not (isinstance(radians, int | float) and math.isfinite(radians)):
            raise PlantError(f"encoder shift must be a finite angle in rad, got {radians!r}")
        self.encoder_shift[f] = float(radians)


class MujocoPlant(_FingerPlant):
    """The MuJoCo hand, stepped by the harness. SI units; fingers 0 thumb .. 4 little."""

    _native: NativeMjPlant

    def __init__(
        self,
        hand: HandGeometry | None = None,
        params: PlantParams | None = None,
        seed: int = 0,
        *,
        obj: objects.GraspObject | str | None = None,
        object_pose: tuple[tuple[float, ...], tuple[float, ...]] | None = None,
        timestep: float = 1e-3,
    ) -> None:
        self._take_hand(hand, params)
        self.names = [f.name for f in self.hand.fingers]
        self.R = np.array([g.guide_radii_m for g in self.geometries])
        self.L = np.array([g.link_lengths_m for g in self.geometries])
        self.q_limits = np.array([g.q_range_m for g in self.geometries])
        xml = mjcf.hand_xml(
            twin_geometry(self.hand, self.params), twin_layout(self.params), drive="force"
        )
        self.object: objects.GraspObject | None = None
        if obj is not None:
            self.object = objects.get_object(obj) if isinstance(obj, str) else obj
            pose = object_pose
            if pose is None and self.object.rest_position_m is not None:
                # where it rests on the palm, as data (objects.toml)
                pose = (self.object.rest_position_m, self.object.rest_quat)
            if pose is None:
                raise PlantError(
                    f"object {self.object.name!r} has no rest_position_m: give object_pose"
                )
            xml = objects.add_object(xml, self.object, pose[0], pose[1], name="object")
            # a weld to the world: an operator's hand keeping the object in place while the
            # fingers close on it (hold_object), off once the grasp has it
            xml = xml.replace(
                "</mujoco>",
                '<equality><weld name="object_held" body1="object" active="false"/></equality>'
                "\n</mujoco>",
            )
        self.xml = xml
        self.model = mujoco.MjModel.from_xml_string(xml)
        #: the longest step MuJoCo takes (the MJCF's timestep): an exchange is cut into steps
        #: no longer than this
        self.max_step_s = float(self.model.opt.timestep)
        self.set_timestep(timestep)
        if self.object is not None:
            # a grasp's friction: elliptic cones and a high impratio keep the contacts from
            # creeping under a steady load (MuJoCo's own advice for grasping)
            self.model.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
            self.model.opt.impratio = IMPRATIO
        if tuple(self.params.gravity_m_s2) == (0.0, 0.0):
            self.model.opt.gravity[:] = 0.0
        # The actuators take the force K i the motor model gives, up to the driver's peak
        # current (MotorParams.peak_force_n): a back-driven motor brakes with more than its
        # stall force. (Clipped at the stall force, a hammer hit on a fingertip sent the
        # antagonist's carriage off with nothing but 100 N to stop it.)
        self.force_limit_n = self.params.motor.peak_force_n
        self.model.actuator_ctrlrange[:] = (-self.force_limit_n, self.force_limit_n)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        m = self.model
        self._j = np.array(
            [[m.jnt_qposadr[m.joint(f"{n}_j{k}").id] for k in (1, 2, 3)] for n in self.names]
        )
        self._jid = np.array([[m.joint(f"{n}_j{k}").id for k in (1, 2, 3)] for n in self.names])
        self._range0 = m.jnt_range[self._jid].copy()
        self._tip_site = [m.site(f"{n}_tip").id for n in self.names]
        self._link3 = [m.body(f"{n}_link3").id for n in self.names]
        self._t1 = [m.tendon(f"{n}_t1").id for n in self.names]
        self._t4 = [m.tendon(f"{n}_t4").id for n in self.names]
        self.frames = [mjcf.finger_frame(m, self.data, n) for n in self.names]
        self._origins = np.array([o for o, _ in self.frames])  # (5, 3): all tips in one go
        self._rots = np.array([r for _, r in self.frames])  # (5, 3, 3)
        self._native = NativeMjPlant(
            libmujoco_path(), m._address, self.data._address, self._c_params(), seed
        )
        self._native.truth_sites(self._tip_site)  # what a run ahead's stops record: the tips
        st = self._native.state
        self.current, self.drive_duty = st["current"], st["drive_duty"]
        self.encoder_shift = st["encoder_shift"]
        self._st = st
        self.tip_force = np.zeros((FINGERS, 2))  # steady tip loads (N, finger frame)
        self._slots: dict[str, int] = {}
        self._block = self.q_limits.copy()

    def _c_params(self) -> MjPlantParamsC:
        m, mot, enc = self.model, self.params.motor, self.params.encoder
        c = MjPlantParamsC()
        act = np.full((FINGERS, 2), -1, dtype=np.int32)
        dof = np.zeros((FINGERS, 2), dtype=np.int32)
        gear = np.zeros((FINGERS, 2))
        for f, spec in enumerate(self.hand.fingers):
            n = spec.name
            names = (
                [f"{n}_motor"] if spec.actuation == "rotary" else [f"{n}_motor_a", f"{n}_motor_b"]
            )
            for k, a in enumerate(names):
                aid = m.actuator(a).id
                act[f, k] = aid
                joint = int(m.actuator_trnid[aid, 0])
                dof[f, k] = int(m.jnt_dofadr[joint])
                gear[f, k] = float(m.actuator_gear[aid, 0])
        np.ctypeslib.as_array(c.actuator)[...] = act
        np.ctypeslib.as_array(c.dof)[...] = dof
        np.ctypeslib.as_array(c.gear)[...] = gear
        np.ctypeslib.as_array(c.j2_qpos)[...] = self._j[:, 1]
        c.supply_v, c.force_constant = mot.supply_v, mot.force_constant_n_a
        c.resistance, c.electrical_time_constant = (
            mot.resistance_ohm,
            mot.electrical_time_constant_s,
        )
        c.stall_force = self.force_limit_n  # the force limit: K times the driver's peak current
        _put_encoder(c, enc)
        return c

    # -- the board's side ----------------------------------------------------------------------
    @property
    def native(self) -> NativeMjPlant:
        return self._native

    def set_timestep(self, seconds: float) -> None:
        """The board's exchange period: MuJoCo takes ``substeps`` equal steps in each, none
        longer than the MJCF's timestep (the harness counts them from the model's timestep)."""
        self.substeps = max(1, math.ceil(float(seconds) / self.max_step_s - 1e-9))
        self.model.opt.timestep = float(seconds) / self.substeps

    def close(self) -> None:
        self._native.close()

    def step(self, dt: float, pins: np.ndarray | None = None) -> None:
        """One exchange period ``dt`` (``substeps`` MuJoCo steps) with the pins held."""
        if dt > 0:
            self._native.step(float(dt), None if pins is None else np.asarray(pins, float))

    # -- observation ----------------------------------------------------------------------------
    @property
    def theta(self) -> np.ndarray:
        """Relative joint angles θ1..θ3 (rad), (5, 3)."""
        return self.data.qpos[self._j].copy()

    @property
    def theta2(self) -> np.ndarray:
        return self.data.qpos[self._j[:, 1]].copy()

    @property
    def q(self) -> np.ndarray:
        """The tendon displacement at Joint 1, R1 θ1 (m)."""
        return self.data.qpos[self._j[:, 0]] * self.R[:, 0]

    def to_finger(self, f: int, world: np.ndarray) -> np.ndarray:
        origin, rot = self.frames[f]
        return rot.T @ (np.asarray(world) - origin)

    @property
    def tip(self) -> np.ndarray:
        """Fingertips in each finger's frame (m), (5, 2)."""
        return self.tip_from(self.data.site_xpos[self._tip_site])

    def tip_from(self, tip_xpos: np.ndarray) -> np.ndarray:
        """:attr:`tip` from the tip sites' world positions (5, 3) (a run ahead's stop's truth)."""
        rel = tip_xpos - self._origins
        return np.einsum("fji,fj->fi", self._rots[:, :, :2], rel)

    @property
    def tension(self) -> np.ndarray:
        """Tendon 1 and Tendon 4 tensions (N), (5, 2): their springs' pull when stretched."""
        k = self.model.tendon_stiffness
        length = self.data.ten_length
        out = np.empty((FINGERS, 2))
        for f in range(FINGERS):
            for c, t in enumerate((self._t1[f], self._t4[f])):
                out[f, c] = k[t] * max(float(length[t]), 0.0)
        return out

    @property
    def applied_force(self) -> np.ndarray:
        """The tip forces (N, finger frame) applied now, a ramp's present value included."""
        out = np.zeros((FINGERS, 2))
        now = self._native.time
        for f in range(FINGERS):
            i = self._slots.get(f"tip{f}")
            if i is not None:
                out[f] = (self.frames[f][1].T @ self._load_now(i, now))[:2]
        return out

    @property
    def blocks(self) -> np.ndarray:
        return self._block.copy()

    # -- set-up and faults ------------------------------------------------------------------------
    def set_theta2(self, finger: int, theta2: float) -> None:
        """Put a finger at rest at a Joint-2 angle on the rigid coupling, tendons just taut."""
        f = _finger_index(finger)
        q = self._q_at_theta2(f, theta2)
        mjcf.set_coupled_pose(self.model, self.data, {self.names[f]: q}, self.hand)
        self.current[f] = 0.0

    def block(self, finger: int, theta2: float | None = None, direction: str = "both") -> None:
        """Block a finger at a Joint-2 angle (default: where it is) by narrowing its joints'
        ranges at the coupled pose there: ``both`` jams it, ``flexion`` stops it flexing."""
        f = _finger_index(finger)
        self._check_direction(direction)
        th2 = self.theta2[f] if theta2 is None else float(theta2)
        q = th2 * self.R[f, 1]
        lo, hi = self.q_limits[f]
        if not lo <= q <= hi:
            raise PlantError(f"finger {f}: cannot block at θ2 = {th2:.3f} rad, outside its range")
        at = q / self.R[f]
        rng = self.model.jnt_range
        for k in range(3):
            j = self._jid[f, k]
            rng[j] = (at[k], at[k]) if direction == "both" else (self._range0[f, k, 0], at[k])
        self._block[f] = (q, q) if direction == "both" else (lo, q)

    def set_closed_stop(self, finger: int, theta2: float) -> None:
        """This build's closed stop: the finger's joints stop flexing at the coupled pose of
        Joint-2 angle ``theta2`` (rad), inside the model's range (a build fault)."""
        f = _finger_index(finger)
        q = self._q_at_theta2(f, theta2)
        at = q / self.R[f]
        for k in range(3):
            self.model.jnt_range[self._jid[f, k], 1] = self._range0[f, k, 1] = at[k]
        self.q_limits[f, 1] = q
        self._block[f] = self.q_limits[f]

    def unblock(self, finger: int) -> None:
        f = _finger_index(finger)
        self.model.jnt_range[self._jid[f]] = self._range0[f]
        self._block[f] = self.q_limits[f]

    # -- loads ------------------------------------------------------------------------------------
    def _slot(self, key: str) -> int:
        if key not in self._slots:
            free = [i for i in range(len(self._st["load_body"])) if i not in self._slots.values()]
            if not free:
                raise PlantError("too many steady loads at once")
            self._slots[key] = free[0]
        return self._slots[key]

    def _world(self, f: int, v: np.ndarray) -> np.ndarray:
        return self.frames[f][1] @ np.array([v[0], v[1], 0.0])

    def set_tip_force(self, finger: int, force_n: tuple[float, float], ramp_s: float = 0.0) -> None:
        """A steady tip force (Fx, Fy) in N, finger frame, at the tip site, reached linearly
        over ``ramp_s`` from the force there now."""
        f = _finger_index(finger)
        fv = _force_vector(force_n, "tip force")
        if not (isinstance(ramp_s, int | float) and math.isfinite(ramp_s) and ramp_s >= 0):
            raise PlantError(f"ramp_s must be a time >= 0 s, got {ramp_s!r}")
        i = self._slot(f"tip{f}")
        st = self._st
        now = self._native.time
        was = self._load_now(i, now)
        st["load_body"][i] = self._link3[f] if (fv.any() or was.any()) else -1
        st["load_site"][i] = self._tip_site[f]
        st["load_from"][i] = was
        st["load_force"][i] = self._world(f, fv)
        st["load_t0"][i], st["load_t1"][i] = now, now + float(ramp_s)
        self.tip_force[f] = fv

    def _load_now(self, i: int, now: float) -> np.ndarray:
        """The world-frame force slot ``i`` applies at time ``now`` (mid-ramp included)."""
        st = self._st
        if st["load_body"][i] < 0:
            return np.zeros(3)
        span = st["load_t1"][i] - st["load_t0"][i]
        a = 1.0 if span <= 0 else min(max((now - st["load_t0"][i]) / span, 0.0), 1.0)
        return st["load_from"][i] + a * (st["load_force"][i] - st["load_from"][i])

    def hit(self, finger: int, impulse_ns: tuple[float, float], duration_s: float = 5e-3) -> None:
        """A hammer hit at the fingertip: (Jx, Jy) N s in the finger frame over ``duration_s``."""
        self._native.hit(*self.hit_args(finger, impulse_ns, duration_s))

    def hit_args(
        self, finger: int, impulse_ns: tuple[float, float], duration_s: float = 5e-3
    ) -> tuple[int, int, np.ndarray, float]:
        """A tip hit as the C plant takes it: body, site, world impulse (N s), duration (s)."""
        f = _finger_index(finger)
        jv = _force_vector(impulse_ns, "impulse")
        if not (
            isinstance(duration_s, int | float) and math.isfinite(duration_s) and duration_s > 0
        ):
            raise PlantError(f"a hit's duration must be > 0 s, got {duration_s!r}")
        return self._link3[f], self._tip_site[f], self._world(f, jv), float(duration_s)

    # -- the object -------------------------------------------------------------------------------
    def _object_body(self) -> int:
        if self.object is None:
            raise PlantError("this plant holds no object (MujocoPlant(obj=...))")
        return self.model.body("object").id

    def hit_object(self, impulse_ns: tuple[float, float, float], duration_s: float = 5e-3) -> None:
        """A hammer hit on the object at its centre of mass: (Jx, Jy, Jz) N s, world frame."""
        body = self._object_body()
        jv = np.asarray(impulse_ns, dtype=float)
        if jv.shape != (3,) or not np.all(np.isfinite(jv)):
            raise PlantError(f"impulse must be three finite numbers (N s), got {impulse_ns!r}")
        self._native.hit(body, -1, jv, float(duration_s))

    def hold_object(self, held: bool) -> None:
        """Keep the object at its placement (welded to the world: an operator holding it while
        the hand closes) or let it go."""
        self._object_body()
        self.data.eq_active[self.model.equality("object_held").id] = int(bool(held))

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The object's position (m) and orientation (w, x, y, z), world frame."""
        b = self._object_body()
        return self.data.xpos[b].copy(), self.data.xquat[b].copy()

    def contact_forces(self) -> np.ndarray:
        """Per finger, the total normal force (N) of its contacts with the object now."""
        b = self._object_body()
        m, d = self.model, self.data
        finger_of = {}
        for f, n in enumerate(self.names):
            for k in (1, 2, 3):
                finger_of[m.body(f"{n}_link{k}").id] = f
        out = np.zeros(FINGERS)
        wrench = np.zeros(6)
        for i in range(d.ncon):
            con = d.contact[i]
            b1, b2 = m.geom_bodyid[con.geom1], m.geom_bodyid[con.geom2]
            other = b2 if b1 == b else b1 if b2 == b else None
            if other is None or other not in finger_of:
                continue
            mujoco.mj_contactForce(m, d, i, wrench)
            out[finger_of[other]] += abs(wrench[0])
        return out
