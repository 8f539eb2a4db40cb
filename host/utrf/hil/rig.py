"""The rig a run talks to: the hand, the tracker, and whoever applies the loads.

"Rig" is the physical set-up of a hardware-in-the-loop run (the hand, its board, the tracker,
the weights); "bench" in this project means a benchmark (``make bench``). On the real rig
(``--port``) an operator hangs the weights and hits the fingers; the run prompts and waits for
a confirmation, and records. On the emulated rig (``--emulated``) the run drives an
:class:`~utrf.emulator.EmulatedBoard` in simulated time (as fast as the machine goes, the same
for a seed) and applies the loads itself; a :class:`SimulatedTracker` reads the plant's
fingertip.

**The emulated truth is not the analysis model.** :class:`EmulatedTruth` holds what the runs
must find out without being told: the coupling tendons' effective modulus (a stranded rope is
softer than its wire: 160 GPa against the model's nominal 200 GPa), the tracker frame's pose
relative to the finger (found by the registration), and the tracker's noise. The firmware's
closed loop on the 10-bit ADC reading of the Joint-2 encoder (7.7 mrad a count, about 2.4 mm
at the straight finger's tip) adds the hold error a real hand has.

**The emulated rig's actuator.** The paper's static loading experiment drove the finger with
a linear slide stage, not with the hand's 12 W motors: holding 3 kg straight needs about
1 kN on the actuating tendon (``docs/models.md``), ten times the hand's assumed 100 N motors.
The emulated rig therefore puts a slide-stage-like actuator on the tested finger's motor A
and B channels (:data:`RIG_ACTUATOR`: 2.5 kN at stall, 50 mm/s, a heavy carriage) and
raises the controller's integral gain for it (:data:`RIG_GAINS`).
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np

from utrf.emulator.plant_params import EncoderParams, MotorParams, PlantParams
from utrf.hil.tracker import (
    Registration,
    SimulatedTracker,
    Tracker,
    TrackerSample,
    rotation_from_euler,
)

if TYPE_CHECKING:
    from utrf.hand.simlink_stops import Stops

#: the emulated static-loading rig's actuator (a linear slide stage; ASSUMED values)
RIG_ACTUATOR = MotorParams(stall_force_n=2500.0, moving_mass_kg=100.0)
T = TypeVar("T")
#: controller gains the emulated rig sets on the tested finger (the rest stay default)
RIG_GAINS: dict[str, float] = {"ki": 20.0}


@dataclass(frozen=True)
class EmulatedTruth:
    """What the emulated rig knows and the analysis must find: SI units."""

    coupling_modulus_pa: float = 160e9
    tracker_euler_rad: tuple[float, float, float] = (0.6, -0.25, 0.15)
    tracker_translation_m: tuple[float, float, float] = (-0.080, 0.210, -0.045)
    tracker_noise_m: float = 1e-4
    actuator: MotorParams | None = field(default_factory=lambda: RIG_ACTUATOR)
    #: the Joint-2 encoders' output noise (V RMS; the plant's default, 0.41 ADC count)
    encoder_noise_v: float = EncoderParams().noise_v

    def plant_params(self) -> PlantParams:
        encoder = EncoderParams(noise_v=self.encoder_noise_v)
        if self.actuator is None:
            return PlantParams(encoder=encoder, coupling_modulus_pa=self.coupling_modulus_pa)
        return PlantParams(
            motor=self.actuator, encoder=encoder, coupling_modulus_pa=self.coupling_modulus_pa
        )

    def tracker_frame(self) -> Registration:
        return Registration(
            rotation_from_euler(*self.tracker_euler_rad), np.asarray(self.tracker_translation_m)
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "coupling_modulus_pa": self.coupling_modulus_pa,
            "tracker_euler_rad": list(self.tracker_euler_rad),
            "tracker_translation_m": list(self.tracker_translation_m),
            "tracker_noise_m": self.tracker_noise_m,
            "encoder_noise_v": self.encoder_noise_v,
            "actuator_stall_force_n": None
            if self.actuator is None
            else self.actuator.stall_force_n,
        }


class Operator(Protocol):
    """The person at the real rig."""

    def confirm(self, text: str) -> None:
        """Show an instruction and wait until it is done."""

    def say(self, text: str) -> None: ...


class ConsoleOperator:
    """Instructions on stdout; Enter confirms. A closed stdin (no operator) raises."""

    def confirm(self, text: str) -> None:
        print(
            f"\n>>> {text}\n    press Enter when done (Ctrl-C stops the run) ", end="", flush=True
        )
        line = sys.stdin.readline()
        if line == "":
            raise EOFError("no operator: stdin is closed, nobody can confirm the rig step")

    def say(self, text: str) -> None:
        print(text, flush=True)


class Rig:
    """A hand, a tracker and the loads on one finger, real or emulated."""

    def __init__(
        self,
        hand: Any,
        tracker: Tracker,
        *,
        board: Any = None,
        operator: Operator | None = None,
        truth: EmulatedTruth | None = None,
        ramp_s: float = 0.5,
        ahead: bool = True,
        tracked_finger: int | None = None,
    ) -> None:
        if board is None and operator is None:
            raise ValueError("a real rig needs an operator to apply the loads")
        self.hand = hand
        self.tracker = tracker
        self.board = board
        self.operator = operator
        self.truth = truth
        self.ramp_s = ramp_s
        #: periodic samples with the board running ahead where it can (:meth:`each_period`)
        self.ahead = ahead
        #: and through many samples a run, the harness taking each one's truth (the fast path)
        self.batched = ahead
        #: the finger the simulated tracker's sensor is on (emulated)
        self.tracked_finger = tracked_finger

    @property
    def emulated(self) -> bool:
        return self.board is not None

    def sleep(self, seconds: float) -> None:
        self.hand.clock.sleep(seconds)

    def now(self) -> float:
        return float(self.hand.clock.now())

    def each_period(
        self,
        t0: float,
        period: float,
        take: Callable[[float], T | None],
        stops: Stops | None = None,
    ) -> Generator[T, None, None]:
        """``take(t)`` at ``t0 + k period`` (k = 1, 2, ...; ``t`` from ``t0``) until it gives
        None; yields what it gives. On the emulated rig (``ahead``) the board runs on to the
        next time on its own thread while the caller works on what was yielded
        (``SimLink.sleep_each``): ``take`` sees the board stopped at its time (read the
        plant, hit it), the caller sees the hand's telemetry up to that time. Otherwise each
        time is slept to, then taken: the same samples (a test compares them). ``stops``
        (:meth:`batch_stops`): what ``take`` does to the plant, for the harness to do at each
        time, the board running through many (``SimLink.stops_each``; :attr:`batched`)."""
        ends = (t0 + k * period for k in itertools.count(1))
        stops_each = getattr(self.hand.clock, "stops_each", None)
        if stops is not None and self.batched and stops_each is not None:
            yield from stops_each(ends, lambda: take(self.now() - t0), stops)
            return
        sleep_each = getattr(self.hand.clock, "sleep_each", None) if self.ahead else None
        if sleep_each is not None:
            yield from sleep_each(ends, lambda: take(self.now() - t0))
            return
        for due in ends:
            self.sleep(due - self.now())
            value = take(self.now() - t0)
            if value is None:
                return
            yield value

    def batch_stops(
        self,
        t0: float,
        last_s: float,
        hits: list[tuple[float, int, tuple[float, float]]],
        duration_s: float,
        made: Callable[[float, Callable[[], TrackerSample], np.ndarray, int], Any],
    ) -> Stops | None:
        """What :meth:`each_period`'s ``take`` does, for the harness (None: not emulated):
        ``hits`` (time from ``t0``, finger, impulse) as :meth:`hit` applies them, and at each
        time ``made(t, reading, currents, hits applied)`` with the tracker's reading
        (:meth:`SimulatedTracker.read_later_at`) and the currents as the truth had them."""
        tracker = self.tracker
        if self.board is None or self.tracked_finger is None:
            return None
        if not isinstance(tracker, SimulatedTracker):
            return None
        plant = self.board.plant
        f = self.tracked_finger
        c_hits = [(at, *plant.hit_args(finger, imp, duration_s)) for at, finger, imp in hits]

        def made_at(now: float, truth: np.ndarray, applied: int) -> Any:
            tip = plant.tip_from(truth[:15].reshape(5, 3))[f]
            reading = tracker.read_later_at(now, tip)
            return made(now - t0, reading, truth[15:25].reshape(5, 2).copy(), applied)

        from utrf.hand.simlink_stops import Stops

        return Stops(t0, c_hits, last_s, made_at)

    def set_payload(self, finger: int, mass_kg: float, previous_kg: float | None) -> None:
        """The payload hanging from the fingertip becomes ``mass_kg`` (total)."""
        if self.board is not None:
            self.board.hang_payload(finger, mass_kg, ramp_s=self.ramp_s)
            self.sleep(self.ramp_s)
            return
        assert self.operator is not None
        name = self.hand.fingers[finger]
        if mass_kg == 0:
            if previous_kg:
                self.operator.confirm(f"REMOVE the weight from the {name} fingertip, gently")
            return
        self.operator.confirm(
            f"Hang {mass_kg * 1e3:.0f} g in total from the {name} fingertip (lower it gently; "
            f"now {0 if previous_kg is None else previous_kg * 1e3:.0f} g)"
        )

    def hit(self, finger: int, impulse_ns: tuple[float, float], duration_s: float) -> None:
        if self.board is None:
            raise RuntimeError(
                "only the emulated rig hits by itself; on the real one, the operator"
            )
        self.board.hit_tip(finger, impulse_ns, duration_s)

    def currents(self) -> np.ndarray:
        """Motor currents (5, 2) in A where they are known (emulated), NaN otherwise."""
        if self.board is None:
            return np.full((5, 2), np.nan)
        return np.asarray(self.board.motor_current)

    def close(self) -> None:
        try:
            self.tracker.close()
        finally:
            try:
                self.hand.close()
            finally:
                if self.board is not None:
                    self.board.close()


def open_emulated(
    *,
    seed: int,
    tracked_finger: int,
    truth: EmulatedTruth | None = None,
    telemetry_hz: int = 100,
    ramp_s: float = 0.5,
    elf: str | None = None,
) -> Rig:
    """A driven emulated board with the emulated truth, a Hand over it, a simulated tracker
    on ``tracked_finger``'s tip."""
    from utrf.emulator import EmulatedBoard
    from utrf.hand import Hand

    truth = truth if truth is not None else EmulatedTruth()
    board = EmulatedBoard(elf, realtime=False, seed=seed, plant_params=truth.plant_params())
    try:
        hand = Hand.emulated(board, telemetry_hz=telemetry_hz)
    except BaseException:
        board.close()
        raise
    tracker = SimulatedTracker(
        lambda: board.tip[tracked_finger],
        lambda: board.sim_time,
        frame=truth.tracker_frame(),
        noise_m=truth.tracker_noise_m,
        seed=seed + 7919,
    )
    return Rig(
        hand, tracker, board=board, truth=truth, ramp_s=ramp_s, tracked_finger=tracked_finger
    )


def open_real(
    port: str,
    tracker: Tracker,
    *,
    operator: Operator | None = None,
    telemetry_hz: int = 100,
    boot_wait_s: float = 2.5,
) -> Rig:
    from utrf.hand import Hand

    hand = Hand.connect(port, telemetry_hz=telemetry_hz, boot_wait_s=boot_wait_s)
    return Rig(hand, tracker, operator=operator or ConsoleOperator())
