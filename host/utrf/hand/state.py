"""What the board reports, by finger name, in SI units.

:class:`HandState` is one ``state`` message (a telemetry sample or a ``get_state`` reply) with
the finger names of the hand, the host's receive time and the board's clock unwrapped (the
wire's 32-bit microsecond counter wraps every 71.6 min; a bench run holding a grasp for
longer must not see time run backwards). :class:`FaultEvent` is one ``fault`` message.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from utrf.protocol import messages as m

BOARD_CLOCK_WRAP_S = 2**32 * 1e-6
CLOSED_LOOP = (m.ControlMode.POSITION, m.ControlMode.GRASP)


def fault_names(bits: int) -> str:
    """``"STALL|JOINT_LIMIT"``, or ``"none"``."""
    names = [f.name for f in m.FaultBits if f & bits and f.name]
    return "|".join(names) if names else "none"


@dataclass(frozen=True, slots=True)
class FingerState:
    """One finger in one sample. Angles in rad, duties as signed fractions, tip in m."""

    name: str
    index: int
    theta2: float  # measured Joint-2 angle
    target: float  # the Joint-2 target the board is using
    duty_a: float  # motor A (flexor, or the rotary motor)
    duty_b: float  # motor B (extensor)
    mode: m.ControlMode
    faults: m.FaultBits
    tip_x: float  # fingertip from the board's kinematics table
    tip_y: float

    @property
    def error(self) -> float:
        """target − measured (rad)."""
        return self.target - self.theta2

    @property
    def closed_loop(self) -> bool:
        return self.mode in CLOSED_LOOP


@dataclass(frozen=True, slots=True)
class HandState:
    """The five fingers at one board time."""

    board_time: float  # s, unwrapped board clock at the sample
    host_time: float  # s, when it arrived (see Clock.timestamp)
    seq: int | None  # the stream seq, None for a get_state reply
    fingers: tuple[FingerState, ...]

    def __getitem__(self, key: int | str) -> FingerState:
        if isinstance(key, str):
            for f in self.fingers:
                if f.name == key:
                    return f
            raise KeyError(f"no finger named {key!r}; fingers are {self.names}")
        return self.fingers[key]

    def __iter__(self) -> Iterator[FingerState]:
        return iter(self.fingers)

    def __len__(self) -> int:
        return len(self.fingers)

    @property
    def names(self) -> list[str]:
        return [f.name for f in self.fingers]

    @property
    def theta2(self) -> np.ndarray:
        return np.array([f.theta2 for f in self.fingers])

    @property
    def target(self) -> np.ndarray:
        return np.array([f.target for f in self.fingers])

    @property
    def faulted(self) -> list[FingerState]:
        return [f for f in self.fingers if f.faults]

    @classmethod
    def from_message(
        cls,
        msg: m.State,
        names: Sequence[str],
        *,
        board_time: float | None = None,
        host_time: float = math.nan,
        seq: int | None = None,
    ) -> HandState:
        fingers = tuple(
            FingerState(
                name=names[i],
                index=i,
                theta2=msg.theta2[i],
                target=msg.target[i],
                duty_a=msg.duty_a[i],
                duty_b=msg.duty_b[i],
                mode=m.ControlMode(msg.mode[i]),
                faults=m.FaultBits(msg.faults[i]),
                tip_x=msg.tip_x[i],
                tip_y=msg.tip_y[i],
            )
            for i in range(len(names))
        )
        return cls(
            board_time=msg.board_time if board_time is None else board_time,
            host_time=host_time,
            seq=seq,
            fingers=fingers,
        )


@dataclass(frozen=True, slots=True)
class FaultEvent:
    """A finger latched new faults (the board's ``fault`` message)."""

    finger: str
    index: int
    new_faults: m.FaultBits
    faults: dict[str, m.FaultBits]  # every finger's latched faults
    board_time: float
    host_time: float

    def __str__(self) -> str:
        return (
            f"finger {self.finger!r} latched {fault_names(self.new_faults)} "
            f"at board time {self.board_time:.3f} s"
        )


class BoardClock:
    """Unwraps the board's 32-bit microsecond clock. A ``boot`` starts it again at 0."""

    def __init__(self) -> None:
        self._offset = 0.0
        self._last: float | None = None

    def restart(self) -> None:
        self._offset = 0.0
        self._last = None

    def unwrap(self, raw: float) -> float:
        if self._last is not None and raw < self._last - BOARD_CLOCK_WRAP_S / 2:
            self._offset += BOARD_CLOCK_WRAP_S
        self._last = raw
        return raw + self._offset
