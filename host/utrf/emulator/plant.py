"""The physical hand behind the emulated board: five tendon-driven fingers, their motors and
encoders, vectorised over the fingers with numpy.

Per finger (paper Sec. II, IV-B):

* **Drive.** Each TB6612FNG channel is decoded from the board's pins (truth table in
  ``docs/architecture.md``): IN1/IN2 = H/L drives forward at the PWM duty (and short-brakes
  in the PWM's off time), L/H reverse, H/H short brake, L/L or STBY low coast (outputs off).
  At 20 kHz the PWM is far faster than the motor's electrical time constant, so the motor
  sees the average voltage ``duty * V``; "forward" pulls the motor's tendon.
* **Motors.** DC linear actuators (lead screw), one per tendon: antagonistic fingers have
  motor A on Tendon 1 (flexion) and motor B on Tendon 4 (extension); a rotary finger has one
  motor winding both tendons on its bending pulley (modelled at the pulley rim, B unused).
  ``L di/dt = u V − R i − K v``, force ``K i``, a reflected moving mass, Coulomb and viscous
  friction, a stroke with hard ends. Coasting opens the circuit (no current).
* **Tendons.** Steel, elastic (``k = E A / L_T``, paper: 1 mm, 200 GPa, 100 mm) with a little
  internal damping; they pull only when taut (stretch ``x_A − q`` for Tendon 1, ``x_B + q``
  for Tendon 4). The coupling tendons are taken as rigid, so θ_i = q / R_i exactly (their
  stretch under the hand's own weight is below a micrometre).
* **Finger.** One degree of freedom, the tendon displacement q: ``M(q) q̈ + ½ M'(q) q̇² = T1 −
  T4 + Q_gravity(q) − b q̇``, with M(q) from the link masses and the coupled kinematics
  (``utrf.models``), joint damping summed through the coupling (``b = Σ c_j / R_j²``) and hard
  joint limits at θ1's range (paper: ±90°).
* **Encoder.** An AS5600 on Joint 2 in analog mode: 12-bit angle, output 10–90 % of 5 V over
  one turn, seeded Gaussian noise. The board's ADC quantises it to 10 bits.
* **Tip loads.** An external force at each fingertip (a payload's weight, any direction,
  ramped in as an operator lowers a weight) plus short force pulses (hammer hits). The motor
  and the controller feel it through the coupling: its generalised force on q is the tip
  Jacobian's transpose times the force. The payload acts by its weight only (its inertia,
  a weight hanging on a cord, is not modelled).
* **Coupling stretch under tip loads.** The coupling tendons stay rigid in the dynamics, but
  under a tip load they stretch quasi-statically (their resonance, ~1 kHz, is far above the
  loop's): the net tensions of the statics (``N3 = −τ3/R3``, ``N2 = N3 − τ2/R2``) stretch
  Tendon 2 and 3 by ``e = N L_T / (E A)``, with ``PlantParams.coupling_modulus_pa`` (the
  hidden "true" effective modulus of an emulated bench; default: the geometry's). The joints
  then sit at ``R1 θ1 = q``, ``R2 θ2 = q − e2``, ``R3 θ3 = q − e2 − e3``, so the Joint-2
  encoder, the joint angles and the tip all see it, and a controller holding θ2 holds the
  stretched finger. The links' own weight is left out of it (below a micrometre).

Every constant the paper does not give is an assumption, kept in :class:`MotorParams`,
:class:`EncoderParams` and :class:`PlantParams` and documented in ``README.md``.

The dynamics run in C (``harness/plant.c``), so the board steps the plant in lockstep with the
MCU without crossing into Python; this module computes the constants from the geometry and
reads and writes the C state in place (numpy views).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from utrf.emulator._native import MjPlantParamsC, NativePlant, PlantParamsC, _NativeStepper
from utrf.models import tendons
from utrf.models.geometry import HandGeometry

FINGERS = 5
_SIDE = np.array([-1.0, 1.0])  # Tendon 1 shortens as q grows, Tendon 4 lengthens
COAST, BRAKE, FORWARD, REVERSE = 0, 1, 2, 3
DRIVE_NAMES = ("coast", "brake", "forward", "reverse")


class PlantError(ValueError):
    """A plant parameter or request that does not describe the hand."""


def _positive(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise PlantError(f"{name} must be a number > 0, got {value!r}")


@dataclass(frozen=True)
class MotorParams:
    """A small 12 V DC linear actuator, one per tendon. ASSUMED values (the paper names none):
    100 N stall force and 50 mm/s no-load speed at 12 V (stall current 0.42 A, within the
    TB6612's 1.2 A), 0.5 ms electrical time constant, 20 kg of rotor inertia reflected through
    the lead screw (a 10 ms mechanical time constant), 1.5 N Coulomb friction (backdrivable:
    the antagonist's tendon pulls it back), 50 mm stroke centred on the straight finger. The
    TB6612FNG's 3.2 A peak output current bounds the force (``peak_force_n``): a back-driven
    motor brakes with more than its stall force, i = (u V − K v) / R passing the stall current
    when v runs against u."""

    supply_v: float = 12.0
    stall_force_n: float = 100.0
    no_load_speed_m_s: float = 0.050
    electrical_time_constant_s: float = 0.5e-3
    moving_mass_kg: float = 20.0
    coulomb_friction_n: float = 1.5
    viscous_friction_n_s_m: float = 5.0
    stroke_m: tuple[float, float] = (-0.025, 0.025)
    driver_peak_current_a: float = 3.2

    def __post_init__(self) -> None:
        for name in (
            "supply_v",
            "driver_peak_current_a",
            "stall_force_n",
            "no_load_speed_m_s",
            "electrical_time_constant_s",
            "moving_mass_kg",
        ):
            _positive(f"MotorParams.{name}", getattr(self, name))
        for name in ("coulomb_friction_n", "viscous_friction_n_s_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise PlantError(f"MotorParams.{name} must be >= 0, got {v!r}")
        lo, hi = self.stroke_m
        if not lo < hi:
            raise PlantError(
                f"MotorParams.stroke_m must be (min, max) with min < max, got {self.stroke_m}"
            )

    @property
    def force_constant_n_a(self) -> float:
        """K: force per ampere, equal to the back-EMF per m/s (V s/m)."""
        return self.supply_v / self.no_load_speed_m_s

    @property
    def stall_current_a(self) -> float:
        return self.stall_force_n / self.force_constant_n_a

    @property
    def resistance_ohm(self) -> float:
        return self.supply_v / self.stall_current_a

    @property
    def peak_force_n(self) -> float:
        """The most force the motor gives or brakes with: K times the driver's peak current
        (never below the stall force)."""
        return max(self.force_constant_n_a * self.driver_peak_current_a, self.stall_force_n)


@dataclass(frozen=True)
class EncoderParams:
    """AS5600 in analog mode on Joint 2. ``offset_rad`` is the encoder's reading at θ2 = 0:
    π puts the straight finger mid-turn, so θ2's whole range (within ±180°: ±95° with the
    default geometry) never wraps; the firmware's ``encoder_offset`` must match it."""

    supply_v: float = 5.0
    offset_rad: float = math.pi
    invert: bool = False
    resolution_bits: int = 12
    band: tuple[float, float] = (0.10, 0.90)
    noise_v: float = 0.002
    unplugged_v: float = 0.0

    def __post_init__(self) -> None:
        _positive("EncoderParams.supply_v", self.supply_v)
        if not (0.0 <= self.band[0] < self.band[1] <= 1.0):
            raise PlantError(f"EncoderParams.band must be 0 <= lo < hi <= 1, got {self.band}")
        if not (1 <= self.resolution_bits <= 16):
            raise PlantError(
                f"EncoderParams.resolution_bits must be 1..16, got {self.resolution_bits}"
            )
        if not (math.isfinite(self.noise_v) and self.noise_v >= 0):
            raise PlantError(f"EncoderParams.noise_v must be >= 0, got {self.noise_v!r}")


@dataclass(frozen=True)
class PlantParams:
    """Constants of the plant that the geometry files do not hold (ASSUMED unless noted).

    ``gravity_m_s2`` is in the finger frame (x along the straight finger, y toward flexion):
    the default is the bench's, gravity along −y (``docs/architecture.md``)."""

    motor: MotorParams = field(default_factory=MotorParams)
    encoder: EncoderParams = field(default_factory=EncoderParams)
    joint_damping_n_m_s: float = 2e-3
    tendon_damping_n_s_m: float = 400.0
    gravity_m_s2: tuple[float, float] = (0.0, -9.81)
    #: the coupling tendons' effective Young's modulus (Pa) for their stretch under tip
    #: loads; None: each finger's geometry value (``tendon_youngs_modulus_pa``)
    coupling_modulus_pa: float | None = None

    def __post_init__(self) -> None:
        for name in ("joint_damping_n_m_s", "tendon_damping_n_s_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise PlantError(f"PlantParams.{name} must be >= 0, got {v!r}")
        if self.coupling_modulus_pa is not None:
            _positive("PlantParams.coupling_modulus_pa", self.coupling_modulus_pa)
        if len(self.gravity_m_s2) != 2 or not all(math.isfinite(g) for g in self.gravity_m_s2):
            raise PlantError(
                f"PlantParams.gravity_m_s2 must be (gx, gy), got {self.gravity_m_s2!r}"
            )


def _force_vector(value: tuple[float, float], what: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise PlantError(f"{what} must be two numbers (x, y), got {value!r}") from None
    if v.shape != (2,) or not np.all(np.isfinite(v)):
        raise PlantError(f"{what} must be two finite numbers (x, y), got {value!r}")
    return v


def _finger_index(finger: int) -> int:
    if (
        isinstance(finger, bool)
        or not isinstance(finger, int | np.integer)
        or not 0 <= finger < FINGERS
    ):
        raise PlantError(f"finger must be 0..4 (0 thumb .. 4 little), got {finger!r}")
    return int(finger)


def _put_encoder(c: PlantParamsC | MjPlantParamsC, e: EncoderParams) -> None:
    """The encoder's constants into either C plant's parameters (the same ``enc_*`` fields)."""
    c.enc_supply, c.enc_offset = e.supply_v, e.offset_rad
    np.ctypeslib.as_array(c.enc_band)[...] = e.band
    c.enc_noise_v, c.enc_unplugged_v = e.noise_v, e.unplugged_v
    c.enc_invert, c.enc_bits = int(e.invert), e.resolution_bits


class _FingerPlant:
    """What both plants (:class:`HandPlant`, the MuJoCo one) share: the hand they take, the
    range check on a Joint-2 angle, and the encoder faults, so both accept the same input."""

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


class HandPlant(_FingerPlant):
    """State and dynamics of the five fingers. SI units: m, rad, N, A, s.

    ``step(dt, pins)`` advances by ``dt`` with the board's pins held (the (5, 2, 4) block of
    duty, IN1, IN2, STBY per finger and channel); ``encoder_volts()`` gives the encoders'
    outputs. The state arrays (``q``, ``qd``, ``x``, ``xd``, ``current``, ``tension``, ...)
    are views of the C plant's memory: read them, or write them and call :meth:`refresh`.
    """

    _native: NativePlant

    def __init__(
        self, hand: HandGeometry | None = None, params: PlantParams | None = None, seed: int = 0
    ) -> None:
        self._take_hand(hand, params)
        g = self.geometries
        self.R = np.array([x.guide_radii_m for x in g])  # (5, 3)
        self.L = np.array([x.link_lengths_m for x in g])
        self.link_mass = np.array([x.link_masses_kg for x in g])
        self.com = np.array([x.link_com_fraction for x in g])
        self.c = np.cumsum(1.0 / self.R, axis=1)  # dφ_k/dq, φ_k the link's absolute angle
        # Centre of mass of link k: p_k = Σ_j A[k, j] (cos φ_j, sin φ_j).
        A = np.zeros((FINGERS, 3, 3))
        for k in range(3):
            A[:, k, :k] = self.L[:, :k]
            A[:, k, k] = self.com[:, k] * self.L[:, k]
        self._A = A
        self._Ac = A * self.c[:, None, :]
        rod_inertia = self.link_mass * self.L**2 / 12.0  # slender links about their centres
        self._rot_inertia = (rod_inertia * self.c**2).sum(axis=1)
        self.tendon_stiffness = np.array(
            [x.tendon_youngs_modulus_pa * x.tendon_area_m2 / x.actuating_tendon_length_m for x in g]
        )
        modulus = np.array(
            [
                x.tendon_youngs_modulus_pa
                if self.params.coupling_modulus_pa is None
                else self.params.coupling_modulus_pa
                for x in g
            ]
        )
        area = np.array([x.tendon_area_m2 for x in g])
        rest = np.array([tendons.rest_lengths(x) for x in g])  # (5, 3): T1, T2, T3
        self.coupling_compliance = rest[:, 1:] / (modulus * area)[:, None]  # m/N, T2 and T3
        self.rotary = np.array([f.actuation == "rotary" for f in self.hand.fingers])
        self.q_limits = np.array([x.q_range_m for x in g])  # (5, 2)
        self._gravity = np.asarray(self.params.gravity_m_s2, dtype=float)
        self._max_substep = self._stable_substep()
        self._native = NativePlant(self._c_params(), seed)
        st = self._native.state
        self.q, self.qd, self.x, self.xd = st["q"], st["qd"], st["x"], st["xd"]
        self.current, self.tension = st["current"], st["tension"]
        self.drive_duty = st["drive_duty"]
        self.tip_force, self.applied_force = st["tip_force"], st["applied_force"]
        self.coupling_stretch = st["coupling_stretch"]
        self.encoder_shift = st["encoder_shift"]
        self._st = st

    def _c_params(self) -> PlantParamsC:
        m, p = self.params.motor, self.params
        c = PlantParamsC()

        def put(field: object, values: np.ndarray) -> None:
            np.ctypeslib.as_array(field)[...] = values

        put(c.R, self.R)
        put(c.L, self.L)
        put(c.link_mass, self.link_mass)
        put(c.com, self.com)
        put(c.tendon_stiffness, self.tendon_stiffness)
        put(c.coupling_compliance, self.coupling_compliance)
        put(c.rotary, self.rotary.astype(np.int32))
        put(c.q_limits, self.q_limits)
        c.supply_v, c.stall_force = m.supply_v, m.stall_force_n
        c.no_load_speed = m.no_load_speed_m_s
        c.electrical_time_constant = m.electrical_time_constant_s
        c.moving_mass = m.moving_mass_kg
        c.coulomb_friction, c.viscous_friction = m.coulomb_friction_n, m.viscous_friction_n_s_m
        put(c.stroke, np.array(m.stroke_m))
        _put_encoder(c, self.params.encoder)
        c.joint_damping, c.tendon_damping = p.joint_damping_n_m_s, p.tendon_damping_n_s_m
        put(c.gravity, self._gravity)
        c.max_substep = self._max_substep
        return c

    @property
    def native(self) -> NativePlant:
        """The C plant, for the board to attach."""
        return self._native

    def close(self) -> None:
        """Free the C plant (the state arrays keep their last values)."""
        self._native.close()
        st = self._native.state
        self.q, self.qd, self.x, self.xd = st["q"], st["qd"], st["x"], st["xd"]

    # -- set-up ---------------------------------------------------------------------------------
    def _inertia(self, q: np.ndarray) -> np.ndarray:
        phi = q[:, None] * self.c
        J = self._Ac @ np.stack((-np.sin(phi), np.cos(phi)), axis=-1)
        return (self.link_mass[:, :, None] * J * J).sum(axis=(1, 2)) + self._rot_inertia

    def _stable_substep(self) -> float:
        """The largest integration step for the stiffest mode, a taut tendon pair between the
        finger's smallest effective mass and the actuator's: ω h ≤ 0.7 (semi-implicit Euler is
        stable to 2, and its frequency error is then 2 %), and the tendon damping's explicit
        term well inside its limit."""
        grid = np.linspace(self.q_limits[:, 0], self.q_limits[:, 1], 181)  # (181, 5)
        m_min = min(float(self._inertia(row).min()) for row in grid)
        k = float(self.tendon_stiffness.max())
        inv_mass = 1.0 / m_min + 1.0 / self.params.motor.moving_mass_kg
        omega = math.sqrt(2.0 * k * inv_mass)
        damping = self.params.tendon_damping_n_s_m * 2.0 * inv_mass
        return min(0.7 / omega, 0.5 / damping if damping > 0 else math.inf)

    @property
    def max_substep(self) -> float:
        """The integration step the plant keeps under (s)."""
        return self._max_substep

    def refresh(self) -> None:
        """Recompute the terms that depend on q, after writing the state."""
        self._native.refresh()

    # -- the board's side -----------------------------------------------------------------------
    def decode_drive(self, pins: np.ndarray) -> None:
        """TB6612FNG truth table, per channel, from the (5, 2, 4) pin block."""
        self._native.decode(np.asarray(pins, dtype=float).reshape(FINGERS, 2, 4))

    def step(self, dt: float, pins: np.ndarray | None = None) -> None:
        """Advance by dt seconds with the pins held (None: keep the last drive)."""
        if not dt > 0:
            return
        if pins is not None:
            pins = np.asarray(pins, dtype=float).reshape(FINGERS, 2, 4)
        self._native.step(float(dt), pins)

    # -- observations ---------------------------------------------------------------------------
    @property
    def theta(self) -> np.ndarray:
        """Relative joint angles θ1..θ3 per finger (rad), shape (5, 3): θ_k = q / R_k, less
        the coupling tendons' stretch under a tip load."""
        e = self.coupling_stretch
        shift = np.column_stack((np.zeros(FINGERS), e[:, 0], e[:, 0] + e[:, 1]))
        return (self.q[:, None] - shift) / self.R

    @property
    def theta2(self) -> np.ndarray:
        return (self.q - self.coupling_stretch[:, 0]) / self.R[:, 1]

    def _phi(self) -> np.ndarray:
        """Absolute link angles (5, 3) with the coupling stretch."""
        return np.cumsum(self.theta, axis=1)

    @property
    def tip(self) -> np.ndarray:
        """Fingertips in each finger's frame (m), shape (5, 2): Eq. 1 at the joint angles
        (``utrf.models.kinematics`` for the rigid finger)."""
        phi = self._phi()
        return np.stack(
            ((self.L * np.cos(phi)).sum(axis=1), (self.L * np.sin(phi)).sum(axis=1)), axis=-1
        )

    @property
    def generalised_tip_force(self) -> np.ndarray:
        """The tip force's generalised force on q (N), per finger: J_tipᵀ F."""
        return self._st["q_ext"].copy()

    # -- tip loads --------------------------------------------------------------------------------
    def set_tip_force(self, finger: int, force_n: tuple[float, float], ramp_s: float = 0.0) -> None:
        """Apply a steady tip force (Fx, Fy) in N, finger frame (a payload of m kg is
        (0, −m g)), reached linearly over ``ramp_s`` s (0: at once), as an operator lowers a
        weight onto a cord. (0, 0) removes it."""
        f = _finger_index(finger)
        fv = _force_vector(force_n, "tip force")
        if not (isinstance(ramp_s, int | float) and math.isfinite(ramp_s) and ramp_s >= 0):
            raise PlantError(f"ramp_s must be a duration >= 0 s, got {ramp_s!r}")
        st = self._st
        st["tip_goal"][f] = fv
        dist = float(np.hypot(*(fv - st["tip_force"][f])))
        st["tip_rate"][f] = dist / ramp_s if ramp_s > 0 else np.inf
        if ramp_s == 0:
            st["tip_force"][f] = fv

    def hit(self, finger: int, impulse_ns: tuple[float, float], duration_s: float = 5e-3) -> None:
        """A hammer hit on the tip: a force pulse carrying ``impulse_ns`` (Jx, Jy) in N s,
        finger frame, spread evenly over ``duration_s`` starting now."""
        f = _finger_index(finger)
        jv = _force_vector(impulse_ns, "impulse")
        if not (
            isinstance(duration_s, int | float) and math.isfinite(duration_s) and duration_s > 0
        ):
            raise PlantError(f"a hit's duration must be > 0 s, got {duration_s!r}")
        self._native.hit(f, float(jv[0]), float(jv[1]), float(duration_s))

    def energy(self) -> tuple[float, float]:
        """(kinetic, potential) energy of the whole hand in J: links, actuators, taut tendons
        and gravity (zero at the straight finger's height). For checking the integrator."""
        M = self._inertia(self.q)
        xd = self.xd.copy()
        xd[self.rotary, 1] = 0.0
        ma = self.params.motor.moving_mass_kg
        kinetic = 0.5 * (M * self.qd**2).sum() + 0.5 * ma * (xd**2).sum()
        phi = self.q[:, None] * self.c
        com = self._A @ np.stack((np.cos(phi), np.sin(phi)), axis=-1)  # (5, 3, 2)
        potential = -(self.link_mass[:, :, None] * com @ self._gravity).sum()
        xb = np.where(self.rotary, -self.x[:, 0], self.x[:, 1])
        stretch = np.maximum(np.stack((self.x[:, 0] - self.q, xb + self.q), axis=1), 0.0)
        potential += 0.5 * (self.tendon_stiffness[:, None] * stretch**2).sum()
        return float(kinetic), float(potential)

    # -- set-up and faults ------------------------------------------------------------------------
    def set_theta2(self, finger: int, theta2: float) -> None:
        """Put a finger at rest at a Joint-2 angle with both tendons just taut."""
        f = _finger_index(finger)
        lo, hi = self.q_limits[f]
        q = min(max(self._q_at_theta2(f, theta2) + self.coupling_stretch[f, 0], lo), hi)
        self.q[f], self.qd[f] = q, 0.0
        self.x[f] = (q, -q)
        self.xd[f] = 0.0
        self.current[f] = 0.0
        self.refresh()

    @property
    def encoder_plugged(self) -> np.ndarray:
        return self._st["plugged"] > 0.5

    def block(self, finger: int, theta2: float | None = None, direction: str = "both") -> None:
        """Block a finger at a Joint-2 angle (default: where it is). ``both``: jammed there;
        ``flexion``: an obstacle stops it flexing further (it can still open). A finger beyond
        the angle is pushed to it."""
        f = _finger_index(finger)
        self._check_direction(direction)
        q = self.q[f] if theta2 is None else float(theta2) * self.R[f, 1]
        lo, hi = self.q_limits[f]
        if not lo <= q <= hi:
            raise PlantError(
                f"finger {f}: cannot block at θ2 = {q / self.R[f, 1]:.3f} rad, outside its range"
            )
        self._st["block"][f] = (q, q) if direction == "both" else (lo, q)

    def unblock(self, finger: int) -> None:
        f = _finger_index(finger)
        self._st["block"][f] = self.q_limits[f]

    @property
    def blocks(self) -> np.ndarray:
        """Each finger's allowed q interval (m), shape (5, 2): its limits narrowed by blocks."""
        return self._st["block"].copy()
