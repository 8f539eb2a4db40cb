"""What the board reports, by finger name, in SI units.

:class:`HandState` is one ``state`` message (a telemetry sample or a ``get_state`` reply) with
the finger names of the hand, the host's receive time and the board's clock unwrapped (the
state's 16-bit millisecond clock wraps every 65.5 s; a bench run holding a grasp for longer
must not see time run backwards). The compact ``state`` leaves out what the host derives or
what rarely changes: each finger's mode and faults come from the latest ``status`` message
(:attr:`HandState.status_current` says whether the sample's ``status_seq`` names it), its tip
from the hand's kinematics (:class:`TipModel`). :class:`FaultEvent` is one ``fault`` message.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as m

#: the fault message's 32-bit microsecond clock
BOARD_CLOCK_WRAP_S = 2**32 * 1e-6
#: the state message's 16-bit millisecond clock
STATE_CLOCK_WRAP_S = 2**16 * 1e-3
#: rows of a tip table: linear interpolation over the Joint-2 range, well under 0.01 mm
TIP_TABLE_ROWS = 2048
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
    tip_x: float  # fingertip, from theta2 by the hand's kinematics (m)
    tip_y: float

    @property
    def error(self) -> float:
        """target − measured (rad)."""
        return self.target - self.theta2

    @property
    def closed_loop(self) -> bool:
        return self.mode in CLOSED_LOOP


def _slot_setters(cls: type) -> tuple[Any, ...]:
    """Each field's slot setter of a slotted dataclass, in field order."""
    return tuple(cls.__dict__[f.name].__set__ for f in fields(cls))


(_NAME, _INDEX, _THETA2, _TARGET, _DUTY_A, _DUTY_B, _MODE, _FAULTS, _TIP_X, _TIP_Y) = _slot_setters(
    FingerState
)


def _finger_state(
    name: str,
    index: int,
    theta2: float,
    target: float,
    duty_a: float,
    duty_b: float,
    mode: m.ControlMode,
    faults: m.FaultBits,
    tip_x: float,
    tip_y: float,
) -> FingerState:
    """``FingerState(...)`` with its slots set directly: the frozen dataclass's ``__init__``
    goes through ``object.__setattr__`` per field, twice the cost, for five a sample at 1 kHz
    (equal objects: test_finger_state_fast_path_equals_the_dataclass)."""
    st = object.__new__(FingerState)
    _NAME(st, name)
    _INDEX(st, index)
    _THETA2(st, theta2)
    _TARGET(st, target)
    _DUTY_A(st, duty_a)
    _DUTY_B(st, duty_b)
    _MODE(st, mode)
    _FAULTS(st, faults)
    _TIP_X(st, tip_x)
    _TIP_Y(st, tip_y)
    return st


@dataclass(frozen=True, slots=True)
class HandState:
    """The five fingers at one board time."""

    board_time: float  # s, unwrapped board clock at the sample
    host_time: float  # s, when it arrived (see Clock.timestamp)
    seq: int | None  # the stream seq, None for a get_state reply
    fingers: tuple[FingerState, ...]
    #: the modes and faults are those of the status the sample names (False: a status
    #: message is missing, they are the last known ones)
    status_current: bool = True

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
        status: m.Status | None,
        tips: TipModel | None = None,
        *,
        board_time: float | None = None,
        host_time: float = math.nan,
        seq: int | None = None,
    ) -> HandState:
        """One sample: ``msg`` with the modes and faults of ``status`` (COAST and no fault
        when None) and the tips of ``tips`` (NaN when None)."""
        n = len(names)
        if tips is not None:
            tip_x, tip_y = tips.tips(msg.theta2[:n])
        else:
            tip_x = tip_y = [math.nan] * n
        modes, faults = _modes_faults(status, n)
        theta2, target, duty_a, duty_b = msg.theta2, msg.target, msg.duty_a, msg.duty_b
        # positional and in a list: each telemetry sample (1 kHz) builds five
        fingers = tuple(
            [
                _finger_state(
                    names[i],
                    i,
                    theta2[i],
                    target[i],
                    duty_a[i],
                    duty_b[i],
                    modes[i],
                    faults[i],
                    float(tip_x[i]),
                    float(tip_y[i]),
                )
                for i in range(n)
            ]
        )
        return cls(
            board_time=msg.board_time if board_time is None else board_time,
            host_time=host_time,
            seq=seq,
            fingers=fingers,
            status_current=status is not None and status.change == msg.status_seq,
        )


#: the last status's modes and faults as enums (a status changes rarely, samples come at 1 kHz)
_last_status: tuple[object, tuple[m.ControlMode, ...], tuple[m.FaultBits, ...]] = (None, (), ())


def _modes_faults(
    status: m.Status | None, n: int
) -> tuple[tuple[m.ControlMode, ...], tuple[m.FaultBits, ...]]:
    """Each finger's mode and faults of ``status`` (COAST and none when None)."""
    global _last_status
    last = _last_status
    if status is not None and last[0] is status and len(last[1]) == n:
        return last[1], last[2]
    if status is None:
        return (m.ControlMode.COAST,) * n, (m.FaultBits(0),) * n
    modes = tuple(m.ControlMode(status.mode[i]) for i in range(n))
    faults = tuple(m.FaultBits(status.faults[i]) for i in range(n))
    _last_status = (status, modes, faults)
    return modes, faults


class TipModel:
    """Each finger's fingertip (x, y) from its Joint-2 angle, by the hand's coupled
    kinematics: what the board used to send, now derived on the host. A table per distinct
    geometry over its Joint-2 range, interpolated linearly (clamped at the ends)."""

    def __init__(self, hand: HandGeometry) -> None:
        tables: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._tables: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for finger in hand.fingers:
            key = id(finger.geometry)
            if key not in tables:
                lo, hi = finger.geometry.theta2_range_rad
                theta2 = np.linspace(lo, hi, TIP_TABLE_ROWS)
                q = kinematics.q_from_theta2(finger.geometry, theta2)
                tip = np.asarray(kinematics.forward(finger.geometry, q).tip, dtype=float)
                tables[key] = (theta2, tip[:, 0].copy(), tip[:, 1].copy())
            self._tables.append(tables[key])
        self._lists = [tuple(a.tolist() for a in t) for t in self._tables]  # for _interp_xy

    def tip(self, finger: int, theta2: float) -> tuple[float, float]:
        """The tip of ``finger`` (0..4) at Joint-2 angle ``theta2`` (rad), in m."""
        grid, x, y = self._lists[finger]
        return _interp_xy(theta2, grid, x, y)

    def tips(self, theta2: Sequence[float]) -> tuple[list[float], list[float]]:
        xs, ys = [], []
        lists = self._lists
        for i, th in enumerate(theta2):
            grid, fx, fy = lists[i]
            x, y = _interp_xy(th, grid, fx, fy)
            xs.append(x)
            ys.append(y)
        return xs, ys


def _interp_xy(
    v: float, grid: list[float], fx: list[float], fy: list[float]
) -> tuple[float, float]:
    """``np.interp(v, grid, fx)`` and ``np.interp(v, grid, fy)`` for one value, in plain floats:
    numpy's own steps (the same result to the bit), one search for both, without numpy's
    per-call cost, for every telemetry sample's five tips."""
    v = float(v)
    if v != v:  # NaN
        return v, v
    j = bisect.bisect_right(grid, v) - 1
    if j < 0:
        return fx[0], fy[0]
    if j >= len(grid) - 1 or grid[j] == v:
        return fx[j], fy[j]
    return _between(v, grid, fx, j), _between(v, grid, fy, j)


def _between(v: float, grid: list[float], f: list[float], j: int) -> float:
    """numpy's interpolation of ``f`` at ``v`` strictly inside ``grid[j]..grid[j + 1]``."""
    slope = (f[j + 1] - f[j]) / (grid[j + 1] - grid[j])
    out = slope * (v - grid[j]) + f[j]
    if out != out:  # NaN one way: numpy tries the other
        out = slope * (v - grid[j + 1]) + f[j + 1]
        if out != out and f[j] == f[j + 1]:
            out = f[j]
    return out


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
    """Unwraps a board clock that wraps every ``wrap_s``. A ``boot`` starts it again at 0.

    Between two readings the clock advanced by their difference modulo the wrap, plus as
    many whole wraps as the host's own clock says passed (so a stream paused for minutes
    does not lose time); with no host time, by less than half a wrap either way.
    """

    def __init__(self, wrap_s: float = BOARD_CLOCK_WRAP_S) -> None:
        self.wrap_s = wrap_s
        self._last_raw: float | None = None
        self._last = 0.0
        self._last_host = math.nan

    def restart(self) -> None:
        self._last_raw = None
        self._last = 0.0
        self._last_host = math.nan

    def unwrap(self, raw: float, host_time: float = math.nan) -> float:
        if self._last_raw is None:
            value = raw
        else:
            step = (raw - self._last_raw) % self.wrap_s
            elapsed = host_time - self._last_host
            if math.isfinite(elapsed):
                step += self.wrap_s * round((elapsed - step) / self.wrap_s)
            elif step > self.wrap_s / 2:
                step -= self.wrap_s
            value = self._last + step
        if self._last_raw is None or value >= self._last:  # an older sample moves nothing
            self._last_raw, self._last, self._last_host = raw, value, host_time
        return value
