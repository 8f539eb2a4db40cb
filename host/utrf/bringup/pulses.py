"""The bring-up's only way to move a finger open loop: a DUTY-mode pulse bounded in duty, time
and travel, watched at the 1 kHz stream and stopped at once on a stall, a latched fault, an
encoder jump or the travel bound; the finger's motors are braked (unpowered, terminals shorted)
when it ends, whatever ended it. The same code runs on the real hand and the emulated board:
it sees only the Hand's telemetry and waits on the Hand's clock.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, replace

import numpy as np

from utrf.hand import Hand
from utrf.hand.errors import FingerFaultError
from utrf.hand.state import HandState

#: how often a pulse looks at what came in (s of the hand's clock)
POLL_S = 0.005


@dataclass(frozen=True)
class Bounds:
    """What a bring-up never exceeds. ``duty``: the largest duty either motor of a finger is
    commanded (pretension included; closed-loop checks run with max_duty at it too);
    ``pulse_s``, ``travel_rad``: one pulse's longest time and Joint-2 travel; a finger driven
    that moves less than ``stall_motion_rad`` in ``stall_s`` is stopped (a stop or a stall);
    a change of more than ``jump_rad`` between two samples stops it too."""

    duty: float = 0.5
    pulse_s: float = 0.4
    travel_rad: float = 0.6
    stall_s: float = 0.15
    stall_motion_rad: float = 0.02
    jump_rad: float = 0.15
    #: the firmware's stall time while bringing up (its own rule behind the host's)
    board_stall_s: float = 0.3


class Recorder:
    """Every telemetry sample since it was attached (a Hand's on_state callback)."""

    def __init__(self, hand: Hand) -> None:
        self.samples: list[HandState] = []
        self._lock = threading.Lock()
        self._detach = hand.on_state(self._take)

    def _take(self, st: HandState) -> None:
        with self._lock:
            self.samples.append(st)

    def mark(self) -> int:
        with self._lock:
            return len(self.samples)

    def since(self, mark: int) -> list[HandState]:
        with self._lock:
            return self.samples[mark:]

    def close(self) -> None:
        self._detach()


@dataclass
class Trace:
    """One pulse (or rest) as the stream saw it: board time (s), every channel's Joint-2
    reading (n, 5) and duties, and why it ended."""

    finger: int
    duty: float
    t: np.ndarray
    theta2: np.ndarray
    duty_a: np.ndarray
    duty_b: np.ndarray
    stop: str

    @classmethod
    def of(cls, finger: int, duty: float, samples: list[HandState], stop: str) -> Trace:
        if not samples:
            z = np.zeros((0, 5))
            return cls(finger, duty, np.zeros(0), z, z, z, stop)
        return cls(
            finger,
            duty,
            np.array([s.board_time for s in samples]),
            np.array([s.theta2 for s in samples]),
            np.array([[f.duty_a for f in s.fingers] for s in samples]),
            np.array([[f.duty_b for f in s.fingers] for s in samples]),
            stop,
        )

    def after(self, t0: float) -> Trace:
        """The samples from board time ``t0`` on (those streamed before a configuration
        change that ``t0`` follows are in the old frame)."""
        keep = self.t >= t0
        return replace(
            self,
            t=self.t[keep],
            theta2=self.theta2[keep],
            duty_a=self.duty_a[keep],
            duty_b=self.duty_b[keep],
        )

    def delta(self) -> np.ndarray:
        """Each channel's change over the trace (rad), (5,)."""
        if len(self.t) < 2:
            return np.zeros(5)
        return self.theta2[-1] - self.theta2[0]

    @property
    def end(self) -> float:
        return float(self.theta2[-1, self.finger]) if len(self.t) else float("nan")

    def to_dict(self) -> dict[str, object]:
        return {
            "finger": self.finger,
            "duty": self.duty,
            "stop": self.stop,
            "t": self.t.tolist(),
            "theta2": self.theta2[:, self.finger].tolist() if len(self.t) else [],
        }


def _why_stop(
    samples: list[HandState], f: int, bounds: Bounds, travel: float, start_s: float
) -> str | None:
    last = samples[-1]
    if last.fingers[f].faults:
        return "fault"
    th = np.array([s.fingers[f].theta2 for s in samples[-3:]])
    if len(th) > 1 and np.max(np.abs(np.diff(th))) > bounds.jump_rad:
        return "jump"
    if abs(last.fingers[f].theta2 - samples[0].fingers[f].theta2) >= travel:
        return "travel"
    now = last.board_time
    if now - start_s >= bounds.stall_s + 0.03:
        window = [s.fingers[f].theta2 for s in samples if s.board_time >= now - bounds.stall_s]
        if window and max(window) - min(window) < bounds.stall_motion_rad:
            return "stall"
    return None


def pulse(
    hand: Hand,
    rec: Recorder,
    finger: int,
    duty: float,
    bounds: Bounds,
    *,
    seconds: float | None = None,
    travel: float | None = None,
    stop_on_stall: bool = True,
    until: float | None = None,
    rest_first: float = 0.0,
) -> Trace:
    """Drive ``finger`` at ``duty`` (DUTY mode: positive pulls Tendon 1) for at most ``seconds``
    (default ``bounds.pulse_s``) and ``travel`` rad (default ``bounds.travel_rad``), or until
    its reading passes ``until`` in the direction it is driven; then brake it. ``duty`` 0:
    a rest (both motors idle, DUTY mode, no stall rule). ``rest_first``: that long at the
    pretension (DUTY 0, the tendons taken up) just before, not braked between (not traced)."""
    if abs(duty) > bounds.duty:
        raise ValueError(f"a bring-up pulse of {duty:+.2f} passes the duty bound {bounds.duty}")
    seconds = bounds.pulse_s if seconds is None else seconds
    travel = bounds.travel_rad if travel is None else travel
    stop = "time"
    try:
        if rest_first > 0:
            hand.set_mode("duty", [finger], duty=0.0)
            hand.clock.sleep(rest_first)
        mark = rec.mark()
        start = hand.state().board_time
        hand.set_mode("duty", [finger], duty=duty)
        while True:
            hand.clock.sleep(POLL_S)
            got = rec.since(mark)
            if not got:
                continue
            why = _why_stop(got, finger, bounds, travel, start)
            if why == "stall" and (not stop_on_stall or duty == 0):
                why = None
            if why is None and until is not None:
                th = got[-1].fingers[finger].theta2
                if (duty > 0 and th >= until) or (duty < 0 and th <= until):
                    why = "reached"
            if why is not None:
                stop = why
                break
            if got[-1].board_time - start >= seconds:
                break
    except FingerFaultError:
        stop = "fault"
    finally:
        brake(hand, [finger])
    return Trace.of(finger, duty, rec.since(mark), stop)


def brake(hand: Hand, fingers: list[int] | None = None) -> None:
    """Motors off (short brake: unpowered; the finger is damped, not held)."""
    hand.set_mode("brake", fingers)


def settle(hand: Hand, seconds: float = 0.1) -> None:
    hand.clock.sleep(seconds)
