"""The constants of the emulated hand that the geometry files do not hold: its motors
(:class:`MotorParams`), its Joint-2 encoders (:class:`EncoderParams`) and the rest of the plant
(:class:`PlantParams`), with the checks that refuse a value that does not describe the hand
(:class:`PlantError`). The MuJoCo plant (``mujoco_plant.py``, ``harness/mjplant.c`` and
``harness/drive.c``) runs on them, and the HIL rig's emulated truth (``utrf.hil.rig``) sets them.

Every constant the paper does not give is an assumption, documented in ``README.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

FINGERS = 5
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
    the default is the bench's, gravity along −y (``docs/architecture.md``). The MuJoCo plant
    takes its gravity from the model (−z in the world); ``(0, 0)`` turns it off, and a hung
    payload weighs ``-gravity_m_s2[1]`` per kg."""

    motor: MotorParams = field(default_factory=MotorParams)
    encoder: EncoderParams = field(default_factory=EncoderParams)
    gravity_m_s2: tuple[float, float] = (0.0, -9.81)
    #: the coupling tendons' effective Young's modulus (Pa) for their stretch under tip
    #: loads; None: each finger's geometry value (``tendon_youngs_modulus_pa``)
    coupling_modulus_pa: float | None = None

    def __post_init__(self) -> None:
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
