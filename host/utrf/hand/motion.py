"""Moves on the board's clock, poses, and waiting for the fingers to settle."""

from __future__ import annotations

import math
import random
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from utrf.hand.control import HandControl, Kind, TargetsArg, control_mode
from utrf.hand.errors import FingerFaultError, NotControlledError, NotSettledError
from utrf.hand.fingers import FingerKey, Fingers, finger_mask
from utrf.hand.goals import Goals
from utrf.hand.limits import JointLimits
from utrf.hand.session import HandSession, log
from utrf.hand.state import CLOSED_LOOP, HandState
from utrf.hand.telemetry import HandTelemetry
from utrf.models.geometry import HandGeometry
from utrf.poses import Pose, PoseLibrary
from utrf.protocol import messages as m
from utrf.protocol.errors import NackError

#: the longest move a command asks for (the protocol's range of move.duration)
MAX_MOVE_S = 60.0
#: a pose's move time when neither the call nor the pose names one
DEFAULT_MOVE_S = 1.0
#: default settling tolerance on the Joint-2 angle: 2 degrees
DEFAULT_TOLERANCE = math.radians(2.0)
#: the take-up at the pretension before a move from motors off: at least, at most (s); still:
#: every finger's reading within ``TAKE_UP_STILL_RAD`` over the last ``TAKE_UP_STILL_S``
TAKE_UP_S = (0.5, 3.0)
TAKE_UP_STILL_RAD = 0.025  # three counts of the reading as it comes (7.7 mrad each)
TAKE_UP_STILL_S = 0.3
#: the modes in which a finger's motors are off (it sags, its tendons go slack)
MOTORS_OFF = (m.ControlMode.COAST, m.ControlMode.BRAKE)


@dataclass(frozen=True)
class MoveResult:
    """The board's answer to a move: per finger moved, its path's duration (s), and the
    fingers whose paths were stretched to keep their speed and acceleration limits."""

    requested: float
    duration: dict[str, float]
    stretched: tuple[str, ...] = ()

    @property
    def longest(self) -> float:
        return max(self.duration.values(), default=0.0)

    def describe(self) -> str:
        if not self.stretched:
            return f"move of {self.longest:.3f} s"
        slow = ", ".join(f"{n} {self.duration[n]:.3f} s" for n in self.stretched)
        return f"move stretched from {self.requested:.3f} s to keep the fingers' limits: {slow}"


def _faulted(st: HandState, idx: Iterable[int]) -> dict[str, int]:
    return {st.fingers[i].name: int(st.fingers[i].faults) for i in idx if st.fingers[i].faults}


class HandMotion:
    """Moves, poses and settling (a part of :class:`~utrf.hand.Hand`)."""

    def __init__(
        self,
        session: HandSession,
        fingers: Fingers,
        geometry: HandGeometry,
        telemetry: HandTelemetry,
        control: HandControl,
        limits: JointLimits,
        goals: Goals,
        poses: PoseLibrary | None = None,
    ) -> None:
        self._session = session
        self._fingers = fingers
        self._geometry = geometry
        self._telemetry = telemetry
        self._control = control
        self._limits = limits
        self._goals = goals
        self._poses = poses
        # A fresh move id per Hand: a board that kept the last session's move cannot take
        # this session's first for a resend of it.
        self._move_id = random.randrange(0x10000)
        self._last_move: MoveResult | None = None

    # --- moves ----------------------------------------------------------------------------------

    def move(
        self,
        targets: TargetsArg,
        duration: float = 1.0,
        *,
        kind: Kind = "theta2",
        wait: bool = True,
        tolerance: float = DEFAULT_TOLERANCE,
        timeout: float | None = None,
        mode: m.ControlMode | str = m.ControlMode.POSITION,
        effort: float = 1.0,
    ) -> MoveResult:
        """Move fingers to targets along minimum-jerk paths of ``duration`` s that the board
        generates on its own clock (one ``move`` command); with ``wait``, then wait until they
        end and :meth:`wait_settled`. ``duration`` 0 asks for the fastest path each finger's
        limits allow (:meth:`motion`); a path faster than they allow is stretched by the board,
        and the result says which fingers and how long their paths take.

        Each finger's path starts from the setpoint the board holds (closed loop) or where it
        is (otherwise), at rest; a finger whose motors are off (COAST, BRAKE) has sagged and
        its tendons are slack, so they are first taken up at the pretension (:meth:`take_up`)
        and its path starts where that leaves it. ``mode``: POSITION, or GRASP with ``effort``
        (the largest closing duty) for the fingers that close by more than ``tolerance`` (those
        that open or stay move in POSITION). Fingers not named keep what they do. A fault
        latched during the move stops it with FingerFaultError.
        """
        if not (math.isfinite(duration) and 0 <= duration <= MAX_MOVE_S):
            raise ValueError(
                f"duration must be a number of seconds in [0, {MAX_MOVE_S:g}], got {duration}"
            )
        mode_ = control_mode(mode)
        if mode_ not in CLOSED_LOOP:
            raise ValueError(f"move needs POSITION or GRASP, got {mode_.name}")
        values = self._control.targets(targets, kind, "move")
        end = {i: self._control.to_theta2(i, v, kind) for i, v in values.items()}
        self._limits.check(end, "move")
        idx = sorted(end)
        st = self._telemetry.state()
        faulted = _faulted(st, idx)
        if faulted:
            raise FingerFaultError(faulted, "move")
        off = [i for i in idx if st.fingers[i].mode in MOTORS_OFF]
        if off:  # else the first closed-loop samples take the slack up against the controller
            self.take_up(off)
            st = self._telemetry.fresh_state(st)
        start = {
            i: (st.fingers[i].target if st.fingers[i].closed_loop else st.fingers[i].theta2)
            for i in idx
        }
        # Fingers not under control yet hold where they are first: their paths start there.
        idle = [i for i in idx if not st.fingers[i].closed_loop]
        if idle:
            self._control.send_joint2(idle, np.array([start[i] for i in idle]))
        seen = self._telemetry.fault_count()
        if mode_ == m.ControlMode.GRASP:
            # GRASP bounds the controller's output both ways: a finger that opens or stays
            # goes in POSITION, so a gentle effort does not leave it lagging on the way out.
            closing = [i for i in idx if end[i] > start[i] + tolerance]
            opening = [i for i in idx if i not in closing]
            closing = [i for i in closing if st.fingers[i].mode != m.ControlMode.GRASP]
            if closing:
                self._control.set_mode(m.ControlMode.GRASP, closing, effort=effort)
        else:
            opening = idx
        todo = [i for i in opening if st.fingers[i].mode != m.ControlMode.POSITION]
        if todo:
            self._control.set_mode(m.ControlMode.POSITION, todo)
        result = self._send_move(idx, end, duration)
        self._goals.set(idx, [end[i] for i in idx])
        if result.stretched:
            log.info("utrf hand: %s", result.describe())
        if wait:
            # The paths end on the board's clock; then the fingers settle.
            self._wait_board_time(st.board_time, result.longest, seen, idx)
            self.wait_settled(
                tolerance,
                timeout if timeout is not None else 3.0,
                fingers=idx,
            )
        else:
            self._telemetry.check_new_faults(seen, idx, "move")
        return result

    def _send_move(
        self, idx: Sequence[int], end: Mapping[int, float], duration: float
    ) -> MoveResult:
        n = len(self._fingers)
        self._move_id = (self._move_id + 1) & 0xFFFF
        try:
            reply = self._session.request(
                m.Move(
                    move_id=self._move_id,
                    kind=m.TargetKind.JOINT2_ANGLE,
                    mask=finger_mask(idx),
                    value=tuple(float(end.get(i, 0.0)) for i in range(n)),
                    duration=tuple(duration if i in end else 0.0 for i in range(n)),
                )
            )
        except NackError as exc:
            if exc.code == m.ErrorCode.FAULTED:
                raise self._telemetry.fault_error(exc, "move") from exc
            raise
        self._last_move = MoveResult(
            requested=duration,
            duration={self._fingers.names[i]: float(reply.duration[i]) for i in idx},
            stretched=tuple(self._fingers.names[i] for i in idx if reply.stretched & (1 << i)),
        )
        return self._last_move

    def _wait_board_time(
        self, since: float, duration: float, seen: int, idx: Sequence[int]
    ) -> None:
        """Until the board's clock passes ``since + duration`` (the paths' end), watching for
        faults. Board time comes from telemetry (or get_state without a stream); the wait
        follows the board's clock, however fast it runs against the host's (an emulated
        board may run slower), and ends early only if that clock stops for a second."""
        clock = self._session.clock
        period = self._telemetry.poll_period()
        st: HandState | None = None
        last_time, last_progress = -math.inf, clock.now()
        while True:
            self._telemetry.check_new_faults(seen, idx, "move")
            st = self._telemetry.fresh_state(st)
            now = clock.now()
            if st.board_time > last_time:
                last_time, last_progress = st.board_time, now
            left = since + duration - st.board_time
            if left <= 0 or now - last_progress > 1.0:
                return
            clock.sleep(min(left, period))  # a fault or reset is seen within a period

    def take_up(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> float:
        """Both motors of ``fingers`` (default all) at the pretension (DUTY 0, open loop, not
        tracking) until their readings are still (``TAKE_UP_*``); they are left so (the next
        mode or move takes over). Returns the board time it took (s)."""
        idx = self._fingers.select(fingers)
        self._control.set_mode(m.ControlMode.DUTY, idx, duty=0.0)
        clock = self._session.clock
        period = self._telemetry.poll_period()
        st = self._telemetry.fresh_state(None)
        start = st.board_time
        seen: list[tuple[float, np.ndarray]] = []
        while True:
            clock.sleep(period)
            st = self._telemetry.fresh_state(st)
            now = st.board_time
            seen.append((now, st.theta2[idx]))
            if now - start >= TAKE_UP_S[1]:
                break
            recent = np.array([th for t, th in seen if t >= now - TAKE_UP_STILL_S])
            ready = now - start >= max(TAKE_UP_S[0], TAKE_UP_STILL_S) and len(recent) > 1
            if ready and float(np.max(np.ptp(recent, axis=0))) < TAKE_UP_STILL_RAD:
                break
        return now - start

    @property
    def last_move(self) -> MoveResult | None:
        """What the board reported for the last move: its paths' durations, which were
        stretched."""
        return self._last_move

    # --- poses and settling ---------------------------------------------------------------------

    @property
    def poses(self) -> PoseLibrary:
        """The pose library (built-in, then ~/.config/utrf/poses.toml), loaded on first use."""
        if self._poses is None:
            self._poses = PoseLibrary.load(hand=self._geometry)
        return self._poses

    def pose(
        self,
        pose: str | Pose,
        duration: float | None = None,
        *,
        wait: bool = True,
        tolerance: float = DEFAULT_TOLERANCE,
        timeout: float | None = None,
    ) -> Pose:
        """Move to a pose of the library (by name) or a :class:`~utrf.poses.Pose`, in one
        :meth:`move` of ``duration`` s (default: the pose's ``duration_s``, else 1 s). A grasp
        pose closes its fingers in GRASP mode with its effort (see :meth:`move`); they count as
        settled when they reach their targets or stop against the object."""
        p = self.poses[pose] if isinstance(pose, str) else pose
        if duration is None:
            duration = p.duration_s if p.duration_s is not None else DEFAULT_MOVE_S
        theta2 = p.theta2(self._geometry)
        if p.grasp is not None:
            self.move(
                list(theta2),
                duration,
                wait=wait,
                tolerance=tolerance,
                timeout=timeout,
                mode=m.ControlMode.GRASP,
                effort=p.grasp.effort,
            )
        else:
            self.move(list(theta2), duration, wait=wait, tolerance=tolerance, timeout=timeout)
        return p

    def wait_settled(
        self,
        tolerance: float = DEFAULT_TOLERANCE,
        timeout: float = 3.0,
        *,
        fingers: Iterable[FingerKey] | FingerKey | None = None,
        settle_time: float = 0.1,
    ) -> HandState:
        """Wait until every finger is within ``tolerance`` (rad) of its target for
        ``settle_time`` s; NotSettledError after ``timeout`` s naming each finger still off and
        by how much. Fingers: those given, else those the Hand has targets for, else those in
        closed loop. The target is the last one commanded (the board's own if none was).
        A GRASP finger also counts as settled when it has stopped (moved less than a quarter of
        the tolerance over ``settle_time``): it holds an object. Raises FingerFaultError when a
        finger latches a fault, NotControlledError when one leaves closed loop."""
        if not tolerance > 0 or not timeout >= 0:
            raise ValueError(f"tolerance must be > 0 and timeout >= 0, got {tolerance}, {timeout}")
        st = self._telemetry.fresh_state(None)
        n = len(self._fingers)
        if fingers is not None:
            idx = self._fingers.select(fingers)
        else:
            idx = self._goals.named() or [i for i in range(n) if st.fingers[i].closed_loop]
        if not idx:
            return st
        clock = self._session.clock
        period = self._telemetry.poll_period()
        start = clock.now()
        ok_since: float | None = None
        history: list[tuple[float, np.ndarray]] = []
        while True:
            now = clock.now()
            st = self._telemetry.fresh_state(st)
            faulted = _faulted(st, idx)
            if faulted:
                raise FingerFaultError(faulted, "wait_settled")
            idle = {
                st.fingers[i].name: st.fingers[i].mode.name
                for i in idx
                if not st.fingers[i].closed_loop
            }
            if idle:
                raise NotControlledError(idle, "wait_settled")
            theta = st.theta2
            history.append((now, theta))
            while history and history[0][0] < now - settle_time - 1e-9:
                history.pop(0)
            goal = np.where(np.isfinite(self._goals.theta2), self._goals.theta2, st.target)
            err = goal - theta
            if now - start >= settle_time and len(history) > 1:
                stopped = np.abs(theta - history[0][1]) < tolerance / 4
            else:
                stopped = np.zeros(n, dtype=bool)
            good = all(
                abs(err[i]) <= tolerance
                or (st.fingers[i].mode == m.ControlMode.GRASP and stopped[i])
                for i in idx
            )
            if good:
                if ok_since is None:
                    ok_since = now
                if now - ok_since >= settle_time:
                    return st
            else:
                ok_since = None
            if now - start >= timeout:
                off = {
                    self._fingers.names[i]: float(err[i]) for i in idx if abs(err[i]) > tolerance
                }
                if not off:  # settled only just now: not for settle_time yet
                    off = {self._fingers.names[i]: float(err[i]) for i in idx}
                raise NotSettledError(off, tolerance, timeout)
            clock.sleep(period)
