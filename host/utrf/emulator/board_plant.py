"""The emulated board's plant knobs: what is done to the hand itself (unplugged or slipped
encoders, blocked fingers, loads and hits at the tips) and its true state as the plant has it
(joint angles, tendon tensions, motor currents and drive). A mixin of
:class:`utrf.emulator.board.EmulatedBoard`; every method holds the board's lock."""

from __future__ import annotations

import math
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any

import numpy as np

from utrf.emulator.board_types import EmulatorError
from utrf.emulator.plant_params import DRIVE_NAMES

if TYPE_CHECKING:
    from utrf.emulator.mujoco_plant import MujocoPlant


class BoardPlant:
    """The plant side of an :class:`~utrf.emulator.board.EmulatedBoard`."""

    if TYPE_CHECKING:  # provided by EmulatedBoard
        _lock: AbstractContextManager[Any]
        plant: MujocoPlant

    def unplug_encoder(self, finger: int, volts: float | None = None) -> None:
        """Finger's Joint-2 encoder disconnected: its ADC input reads ``volts`` (default 0 V)."""
        with self._lock:
            self.plant.unplug_encoder(finger, volts)

    def plug_encoder(self, finger: int) -> None:
        with self._lock:
            self.plant.plug_encoder(finger)

    def block_finger(
        self, finger: int, theta2: float | None = None, direction: str = "both"
    ) -> None:
        """Block a finger at a Joint-2 angle (rad; default where it is): ``both`` jams it,
        ``flexion`` puts an obstacle in its way. Its motor stalls against the block."""
        with self._lock:
            self.plant.block(finger, theta2, direction)

    def unblock_finger(self, finger: int) -> None:
        with self._lock:
            self.plant.unblock(finger)

    def shift_encoder(self, finger: int, radians: float) -> None:
        """The finger's encoder magnet slips: from now its reading is off by ``radians`` (a
        sudden jump of the measured Joint-2 angle; 0 puts it back)."""
        with self._lock:
            self.plant.shift_encoder(finger, radians)

    def set_tip_force(self, finger: int, force_n: tuple[float, float], ramp_s: float = 0.0) -> None:
        """A steady force (Fx, Fy) in N at a fingertip, finger frame (y toward flexion; the
        bench's gravity is −y), reached over ``ramp_s`` s; (0, 0) removes it. The motor and the
        controller feel it through the coupling (``MujocoPlant.set_tip_force``)."""
        with self._lock:
            self.plant.set_tip_force(finger, force_n, ramp_s)

    def hang_payload(self, finger: int, mass_kg: float, ramp_s: float = 0.0) -> None:
        """Hang ``mass_kg`` from a fingertip (its weight along −y of the finger frame, the
        bench's gravity), lowered in over ``ramp_s`` s; 0 removes it."""
        if not (isinstance(mass_kg, int | float) and math.isfinite(mass_kg) and mass_kg >= 0):
            raise EmulatorError(f"a payload must be a mass >= 0 kg, got {mass_kg!r}")
        g = -self.plant.params.gravity_m_s2[1] if self.plant.params.gravity_m_s2[1] else 9.81
        self.set_tip_force(finger, (0.0, -float(mass_kg) * g), ramp_s)

    def hit_tip(
        self, finger: int, impulse_ns: tuple[float, float], duration_s: float = 5e-3
    ) -> None:
        """A hammer hit: a force pulse at the tip carrying ``impulse_ns`` (Jx, Jy) in N s,
        finger frame, over ``duration_s`` from now."""
        with self._lock:
            self.plant.hit(finger, impulse_ns, duration_s)

    @property
    def tip(self) -> np.ndarray:
        """True fingertips (m), shape (5, 2), each in its finger's frame, with the coupling
        tendons' stretch under tip loads: what a perfect tracker would read."""
        with self._lock:
            return self.plant.tip

    @property
    def tip_force(self) -> np.ndarray:
        """The tip force applied over the last step (N), shape (5, 2), pulses included."""
        with self._lock:
            return self.plant.applied_force.copy()

    @property
    def theta(self) -> np.ndarray:
        """True relative joint angles θ1..θ3 (rad), shape (5, 3)."""
        with self._lock:
            return self.plant.theta

    @property
    def theta2(self) -> np.ndarray:
        with self._lock:
            return self.plant.theta2

    @property
    def tendon_tension(self) -> np.ndarray:
        """Tendon 1 (flexor) and Tendon 4 (extensor) tensions (N), shape (5, 2)."""
        with self._lock:
            return self.plant.tension.copy()

    @property
    def motor_current(self) -> np.ndarray:
        """Motor A and B currents (A), shape (5, 2)."""
        with self._lock:
            return self.plant.current.copy()

    @property
    def drive(self) -> list[tuple[tuple[str, float], tuple[str, float]]]:
        """Per finger, (mode, signed duty) of motors A and B as the plant applies them."""
        with self._lock:
            return [
                (
                    (DRIVE_NAMES[int(modes[0])], float(duties[0])),
                    (DRIVE_NAMES[int(modes[1])], float(duties[1])),
                )
                for modes, duties in zip(self.plant.drive_mode, self.plant.drive_duty, strict=True)
            ]
