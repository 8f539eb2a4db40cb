"""A scripted board with a little state, for the Hand's unit tests (no emulator).

It extends the protocol tests' FakeBoard (real framing over TCP) with what a Hand asks for:
limits, targets, modes, faults, get_state, and a telemetry stream at the rate the host sets.
The "plant" is ideal: a finger in POSITION or GRASP is at its target at once, unless a test
holds it (``stuck``). Tests script the rest: refuse, drop or delay any request.
"""

from __future__ import annotations

import math
import threading

from tests.protocol.fake_board import FakeBoard, Reply, identity
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as M
from utrf.protocol.framing import Frame

HAND = HandGeometry.default()
N = 5


class HandBoard(FakeBoard):
    def __init__(self, *, boot_on_connect: bool = False) -> None:
        self.lock = threading.RLock()
        self.theta2 = [0.0] * N
        self.target = [0.0] * N
        self.target_valid = [False] * N  # as the firmware: a target set since leaving control
        self.mode = [M.ControlMode.COAST] * N
        self.faults = [M.FaultBits(0)] * N
        self.stuck: dict[int, float] = {}
        self.limits = [f.geometry.theta2_range_rad for f in HAND.fingers]
        self.safety = M.Safety(heartbeat_timeout=0.5, safe_action=M.SafeAction.HOLD)
        self.rate_hz = 0
        self.board_time = 0.0
        self.change = 0  # the status's change count, as the firmware keeps it
        self._status_sent: tuple = ()
        self.identity = identity()
        self.booted = not boot_on_connect
        self.unheard = 0  # requests sent while the "bootloader" ran: lost
        self._stop = threading.Event()
        super().__init__()
        for cls, handler in (
            (M.Identify, self._identify),
            (M.SetTelemetry, self._set_telemetry),
            (M.GetLimits, self._get_limits),
            (M.SetTargets, self._set_targets),
            (M.SetMode, self._set_mode),
            (M.Move, self._move),
            (M.GetState, self._get_state),
            (M.GetStatus, lambda f: [(f.seq, self.status())]),
            (M.ClearFaults, self._clear_faults),
            (M.GetSafety, lambda f: [(f.seq, self.safety)]),
        ):
            self.on(cls.ID, handler)
        self._streamer = threading.Thread(target=self._stream, daemon=True)
        self._streamer.start()
        if boot_on_connect:
            threading.Thread(target=self._boot_later, daemon=True).start()

    def close(self) -> None:
        self._stop.set()
        super().close()

    # --- what the tests look at ------------------------------------------------------------

    def requests(self, cls: type[M.Message]) -> list[M.Message]:
        with self._got_frame:
            return [cls.decode(f.body) for f in self.received if f.msg_id == cls.ID]

    def latch(self, finger: int, bits: M.FaultBits) -> None:
        with self.lock:
            self.faults[finger] |= bits
            self.mode[finger] = M.ControlMode.COAST
            self.target_valid[finger] = False
            faults = tuple(self.faults)
        self.emit(M.Fault(self.board_time, finger, bits, faults))

    # --- the board -------------------------------------------------------------------------

    def _boot_later(self) -> None:
        if self._connected.wait(5.0):
            self._stop.wait(0.3)  # the bootloader's silence
            self.booted = True
            self.boot(M.ResetCause.RESET_PIN)

    def _identify(self, f: Frame) -> Reply:
        if not self.booted:
            self.unheard += 1
            return None
        return [(f.seq, self.identity)]

    def _set_telemetry(self, f: Frame) -> Reply:
        self.rate_hz = M.SetTelemetry.decode(f.body).rate_hz
        return [(f.seq, M.Ack(f.msg_id))]

    def _get_limits(self, f: Frame) -> Reply:
        i = M.GetLimits.decode(f.body).finger
        lo, hi = self.limits[i]
        return [(f.seq, M.Limits(i, lo, hi, 0.1, 0.2, 0.02, 0.5, 0.2))]

    def _set_targets(self, f: Frame) -> Reply:
        msg = M.SetTargets.decode(f.body)
        new = {}
        for i in range(N):
            if not msg.mask & (1 << i):
                continue
            g = HAND.fingers[i].geometry
            v = msg.value[i]
            if msg.kind == M.TargetKind.TENDON_Q:
                v = float(kinematics.theta2_from_q(g, v))
            elif msg.kind == M.TargetKind.FLEXION:
                if not 0 <= v <= 1:
                    return [(f.seq, M.Nack(f.msg_id, M.ErrorCode.OUT_OF_RANGE, 0x80 | i))]
                v = float(kinematics.theta2_from_q(g, kinematics.q_from_flexion(g, v)))
            lo, hi = self.limits[i]
            if not lo - 1e-4 <= v <= hi + 1e-4:
                return [(f.seq, M.Nack(f.msg_id, M.ErrorCode.OUT_OF_RANGE, 0x80 | i))]
            new[i] = v
        with self.lock:
            for i, v in new.items():
                self.target[i] = v
                self.target_valid[i] = True
            self._settle()
        return [(f.seq, M.Ack(f.msg_id))]

    def _set_mode(self, f: Frame) -> Reply:
        msg = M.SetMode.decode(f.body)
        with self.lock:
            for i in range(N):
                drives = msg.mode[i] in (
                    M.ControlMode.POSITION,
                    M.ControlMode.DUTY,
                    M.ControlMode.GRASP,
                )
                if msg.mask & (1 << i) and drives and self.faults[i]:
                    return [(f.seq, M.Nack(f.msg_id, M.ErrorCode.FAULTED, i))]
            for i in range(N):
                if msg.mask & (1 << i):
                    closed = msg.mode[i] in (M.ControlMode.POSITION, M.ControlMode.GRASP)
                    if closed and not self.target_valid[i]:
                        self.target[i] = self.theta2[i]
                        self.target_valid[i] = True
                    if not closed:
                        self.target_valid[i] = False
                    self.mode[i] = msg.mode[i]
            self._settle()
        return [(f.seq, M.Ack(f.msg_id))]

    #: the limits the fake's moves keep (rad/s, rad/s^2): the firmware's defaults
    max_speed = 1.2
    max_accel = 8.0

    def _move(self, f: Frame) -> Reply:
        """The firmware's checks and stretching rule; the ideal plant is at the end at once."""
        msg = M.Move.decode(f.body)
        assert msg.kind == M.TargetKind.JOINT2_ANGLE  # what the Hand sends
        durations = [0.0] * N
        stretched = 0
        with self.lock:
            for i in range(N):
                if not msg.mask & (1 << i):
                    continue
                lo, hi = self.limits[i]
                if not lo - 1e-4 <= msg.value[i] <= hi + 1e-4:
                    return [(f.seq, M.Nack(f.msg_id, M.ErrorCode.OUT_OF_RANGE, 0x80 | i))]
                if self.faults[i]:
                    return [(f.seq, M.Nack(f.msg_id, M.ErrorCode.FAULTED, i))]
                if self.mode[i] not in (M.ControlMode.POSITION, M.ControlMode.GRASP):
                    return [(f.seq, M.Nack(f.msg_id, M.ErrorCode.BUSY, i))]
                d = abs(msg.value[i] - self.target[i])
                t_min = max(1.875 * d / self.max_speed, math.sqrt(5.7735 * d / self.max_accel))
                t = msg.duration[i]
                if t == 0 or t_min > t + 5e-4:
                    stretched |= (1 << i) if t else 0
                    t = t_min
                durations[i] = math.ceil(t * 1000 - 1e-3) / 1000
            for i in range(N):
                if msg.mask & (1 << i):
                    self.target[i] = msg.value[i]
                    self.target_valid[i] = True
            self._settle()
        return [(f.seq, M.Moving(msg.move_id, stretched, tuple(durations)))]

    def _clear_faults(self, f: Frame) -> Reply:
        mask = M.ClearFaults.decode(f.body).mask
        with self.lock:
            for i in range(N):
                if mask & (1 << i):
                    self.faults[i] = M.FaultBits(0)
        return [(f.seq, M.Ack(f.msg_id))]

    def _settle(self) -> None:
        for i in range(N):
            if self.mode[i] in (M.ControlMode.POSITION, M.ControlMode.GRASP):
                self.theta2[i] = self.stuck.get(i, self.target[i])

    def status(self) -> M.Status:
        """The modes and faults now; a change since the last counts (as on the board)."""
        with self.lock:
            now = (tuple(self.mode), tuple(self.faults))
            if now != self._status_sent:
                self._status_sent = now
                self.change = (self.change + 1) % 256
            return M.Status(change=self.change, mode=now[0], faults=now[1])

    def state(self) -> M.State:
        with self.lock:
            self._settle()
            return M.State(
                board_time=round(self.board_time * 1000) % 65536 / 1000,
                status_seq=self.status().change,
                theta2=tuple(self.theta2),
                target=tuple(self.target),
                duty_a=(0.0,) * N,
                duty_b=(0.0,) * N,
            )

    def _get_state(self, f: Frame) -> Reply:
        return [(f.seq, self.state())]

    def _stream(self) -> None:
        while not self._stop.is_set():
            rate = self.rate_hz
            period = 1.0 / rate if rate else 0.01
            self._stop.wait(period)
            with self.lock:
                self.board_time = (self.board_time + period) % 4294.967296
            if rate and self._connected.is_set():
                try:
                    with self.lock:
                        before = self.change
                        st = self.state()
                        status = self.status() if st.status_seq != before else None
                    if status is not None:
                        self.emit(status)
                    self.emit(st)
                except (OSError, AssertionError):
                    return
