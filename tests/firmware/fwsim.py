"""The firmware core on the host: ctypes over build/firmware/host/libutrf_fw.so.

``Sim`` is one simulated board (the library holds one): power it on, set the encoders' ADC
counts, run ticks and loop() passes, talk to it in protocol frames, and read its motor pins
and finger state. Units at the C boundary are the firmware's own (1e-4 rad, Q16 duty, ADC
counts); the helpers here convert to SI.
"""

from __future__ import annotations

import ctypes
import math
import struct
import subprocess
import tomllib
from dataclasses import dataclass
from pathlib import Path

from utrf.protocol import messages as m
from utrf.protocol.framing import Frame, FrameDecoder, FrameError, encode_frame

REPO = Path(__file__).resolve().parents[2]
LIB_PATH = REPO / "build" / "firmware" / "host" / "libutrf_fw.so"

BU = 2 * math.pi / 32768  # rad per firmware angle unit (binary half-turn)
Q15 = 32768.0  # firmware duty 1.0
PWM_PERIOD = 800
# hal::Drive
COAST, BRAKE, FORWARD, REVERSE = 0, 1, 2, 3


def build_library() -> Path:
    """Build (or bring up to date) the host library with make, as `make test` would."""
    subprocess.run(["make", "--no-print-directory", "-s", "firmware-host"], cwd=REPO, check=True)
    return LIB_PATH


class FwMotor(ctypes.Structure):
    _fields_ = [
        ("drive_a", ctypes.c_uint8),
        ("drive_b", ctypes.c_uint8),
        ("counts_a", ctypes.c_uint16),
        ("counts_b", ctypes.c_uint16),
        ("stby", ctypes.c_uint8),
    ]


class FwFinger(ctypes.Structure):
    _fields_ = [
        ("mode", ctypes.c_uint8),
        ("faults", ctypes.c_uint8),
        ("contact", ctypes.c_uint8),
        ("has_theta", ctypes.c_uint8),
        ("saturated", ctypes.c_uint8),
        ("theta", ctypes.c_int16),  # BU
        ("target", ctypes.c_int16),  # BU
        ("duty_a", ctypes.c_int16),  # Q15
        ("duty_b", ctypes.c_int16),
        ("output", ctypes.c_int16),
        ("limit", ctypes.c_int16),
        ("integrator31", ctypes.c_int32),
    ]

    @property
    def theta_rad(self) -> float:
        return self.theta * BU

    @property
    def target_rad(self) -> float:
        return self.target * BU


class FwStatus(ctypes.Structure):
    _fields_ = [
        ("lock_errors", ctypes.c_uint32),
        ("wdt_feeds", ctypes.c_uint32),
        ("all_off_calls", ctypes.c_uint32),
        ("wdt_started", ctypes.c_uint8),
        ("hang_mark", ctypes.c_uint8),
        ("tick_started", ctypes.c_uint8),
        ("halted", ctypes.c_uint8),
        ("config_status", ctypes.c_uint8),
        ("reset_cause", ctypes.c_uint8),
        ("saving", ctypes.c_uint8),
    ]


def load_library(path: Path = LIB_PATH) -> ctypes.CDLL:
    lib = ctypes.CDLL(str(path))
    c = ctypes
    sig = {
        "fw_power_on": (None, [c.c_uint8]),
        "fw_tick": (None, [c.c_uint32]),
        "fw_loop": (None, [c.c_uint32]),
        "fw_run": (None, [c.c_uint32]),
        "fw_run_woken": (c.c_uint32, [c.c_uint32, c.POINTER(c.c_uint8)]),
        "fw_advance_ms": (None, [c.c_uint32]),
        "fw_set_adc": (None, [c.c_uint8, c.c_uint16]),
        "fw_freeze_adc": (None, [c.c_int]),
        "fw_encoder_general_path": (None, [c.c_int]),
        "fw_safe_action_general_path": (None, [c.c_int]),
        "fw_set_tick_cycles": (None, [c.c_uint32]),
        "fw_set_period_elapsed": (None, [c.c_int]),
        "fw_rx": (c.c_uint16, [c.c_char_p, c.c_uint16]),
        "fw_add_rx_lost": (None, [c.c_uint16]),
        "fw_add_uart_errors": (None, [c.c_uint8, c.c_uint8]),
        "fw_tx": (c.c_uint16, [c.c_char_p, c.c_uint16]),
        "fw_set_tx_room": (None, [c.c_uint16]),
        "fw_eeprom": (c.POINTER(c.c_uint8), []),
        "fw_eeprom_size": (c.c_uint16, []),
        "fw_set_eeprom_busy_polls": (None, [c.c_uint8]),
        "fw_set_eeprom_stuck": (None, [c.c_int32]),
        "fw_eeprom_writes": (c.c_uint32, []),
        "fw_motor": (None, [c.c_uint8, c.POINTER(FwMotor)]),
        "fw_finger": (None, [c.c_uint8, c.POINTER(FwFinger)]),
        "fw_path_ff": (c.c_int16, [c.c_uint8]),
        "fw_path_left": (c.c_uint16, [c.c_uint8]),
        "fw_stream_slots": (c.c_uint8, []),
        "fw_status": (None, [c.POINTER(FwStatus)]),
        "fw_pid_config": (c.c_int, [c.c_char_p, c.c_uint8, c.c_int16]),
        "fw_pid_regain": (c.c_int, [c.c_char_p, c.c_uint8, c.c_int16]),
        "fw_pid_reset": (None, [c.c_int16, c.c_int16]),
        "fw_pid_step": (c.c_int16, [c.c_int16, c.c_int16]),
        "fw_pid_step_open": (c.c_int16, [c.c_int16, c.c_int16]),
        "fw_pid_state": (
            None,
            [c.POINTER(c.c_int32), c.POINTER(c.c_int32), c.POINTER(c.c_int32)],
        ),
        "fw_pid_add_deadband": (c.c_int32, [c.c_int32, c.c_int16]),
        "fw_pid_remove_deadband": (c.c_int16, [c.c_int16, c.c_int16]),
        "fw_gain_roundtrip": (c.c_double, [c.c_double]),
        "fw_gain_apply": (c.c_int32, [c.c_double, c.c_int16, c.c_int32]),
        "fw_gain_paths": (c.c_int, [c.c_double, c.c_int32]),
        "fw_gain_apply_plain": (c.c_int32, [c.c_double, c.c_int16, c.c_int32]),
        "fw_gain_apply16": (c.c_int16, [c.c_double, c.c_int16, c.c_int16]),
        "fw_gain_apply16_hi": (c.c_int16, [c.c_double, c.c_int16, c.c_int16]),
        "fw_gain_apply16_mid": (c.c_int16, [c.c_double, c.c_int16, c.c_int16]),
        "fw_pid_fast_paths": (c.c_int, []),
        "fw_pid_general_path": (None, []),
        "fw_mul_q16": (c.c_int32, [c.c_int32, c.c_uint16]),
        "fw_kin_init": (None, []),
        "fw_kin_geometry": (c.c_uint8, [c.c_uint8]),
        "fw_kin_geometry_count": (c.c_uint8, []),
        "fw_kin_table_bytes": (c.c_uint16, []),
        "fw_kin_range": (None, [c.c_uint8, c.POINTER(c.c_double), c.POINTER(c.c_double)]),
        "fw_kin_lookup": (c.c_int, [c.c_uint8, c.c_double, c.POINTER(c.c_double)]),
        "fw_kin_theta2_from_q": (c.c_int, [c.c_uint8, c.c_double, c.POINTER(c.c_double)]),
        "fw_kin_q_full": (c.c_double, [c.c_uint8]),
        "fw_kin_tip_raw": (
            None,
            [c.c_uint8, c.c_int32, c.POINTER(c.c_int16), c.POINTER(c.c_int16)],
        ),
        "fw_encoder_angle": (c.c_int16, [c.c_uint16, c.c_uint16, c.c_int]),
        "fw_au_from_bu": (c.c_int16, [c.c_int16]),
        "fw_bu": (c.c_int16, [c.c_double]),
        "fw_encoder_turn_from_rad": (c.c_uint16, [c.c_double]),
        "fw_target_window": (
            None,
            [c.c_int16, c.c_int16, c.POINTER(c.c_int32), c.POINTER(c.c_int32)],
        ),
        "fw_target_accepts": (c.c_int, [c.c_int16, c.c_int16, c.c_int32]),
        "fw_config_image_bytes": (c.c_uint16, []),
        "fw_config_body_bytes": (c.c_uint16, []),
    }
    for name, (res, args) in sig.items():
        fn = getattr(lib, name)
        fn.restype = res
        fn.argtypes = args
    return lib


def spec_defaults(message: str) -> dict[str, float]:
    """A message's field defaults, as protocol/spec.toml gives them."""
    spec = tomllib.loads((REPO / "protocol" / "spec.toml").read_text(encoding="utf-8"))
    (msg,) = [x for x in spec["message"] if x["name"] == message]
    return {f["name"]: f["default"] for f in msg["fields"] if "default" in f}


def pid_config(lib: ctypes.CDLL, limit: int, *, regain: bool = False, **gains: float) -> None:
    """The PID alone with these gains (the rest the spec's defaults), as the board compiles a
    set_gains: the C API takes the message's body, so a gain added to the spec needs no change
    here. `regain`: new gains while running (rebased, bumpless)."""
    body = m.SetGains(**{"finger": 0, **spec_defaults("set_gains"), **gains}).encode()
    fn = lib.fw_pid_regain if regain else lib.fw_pid_config
    assert fn(body, len(body), limit) == 0


# ---- encoder voltages ---------------------------------------------------------------------


def adc_for_turn(turn: float) -> float:
    """ADC count (10 bit, fractional) of an AS5600 analog output at `turn` (0..1) of a turn."""
    return 1024.0 * (0.1 + 0.8 * (turn % 1.0))


def adc_for_angle(theta2: float, offset: float = math.pi, invert: bool = False) -> float:
    """ADC count for a Joint-2 angle with the default mounting (straight finger mid-band)."""
    reading = (-theta2 if invert else theta2) + offset
    return adc_for_turn(reading / (2 * math.pi))


@dataclass
class Reply:
    seq: int
    msg: m.Message | None  # None when the body does not decode
    msg_id: int
    body: bytes


class Sim:
    """One simulated board over the host library."""

    def __init__(self, lib: ctypes.CDLL) -> None:
        self.lib = lib
        self._decoder = FrameDecoder()
        self._seq = 0
        self.frames: list[Reply] = []  # everything received and not yet taken
        self.errors: list[FrameError] = []

    # -- power and time --
    def power_on(self, reset_cause: int = 0, *, settle_ms: int = 5) -> None:
        self._decoder = FrameDecoder()
        self.frames.clear()
        self.errors.clear()
        self.lib.fw_power_on(reset_cause)
        self.set_angles([0.0] * 5)
        if settle_ms:
            self.run(settle_ms)

    def run(self, ms: int) -> None:
        """`ms` milliseconds: a tick then a loop() pass each; collects what the board sends
        (often enough that the simulated transmit buffer never fills, as a real line drains)."""
        while ms > 0:
            n = min(ms, 20)
            self.lib.fw_run(n)
            self._drain()
            ms -= n

    def run_woken(self, ms: int) -> tuple[list[bool], int]:
        """`ms` milliseconds as the MEGA runs them: loop() only after the ticks that ask for a
        pass (and on while it finds work). Each tick's asking, and the passes run."""
        woke = (ctypes.c_uint8 * ms)()
        passes = self.lib.fw_run_woken(ms, woke)
        self._drain()
        return [bool(w) for w in woke], passes

    def tick(self, n: int = 1) -> None:
        self.lib.fw_tick(n)

    def loop(self, n: int = 1) -> None:
        self.lib.fw_loop(n)
        self._drain()

    # -- encoders --
    def set_adc(self, finger: int, sample: float) -> None:
        self.lib.fw_set_adc(finger, round(sample))

    def set_angle(self, finger: int, theta2: float, **kw: float) -> None:
        self.set_adc(finger, adc_for_angle(theta2, **kw))

    def set_angles(self, thetas: list[float]) -> None:
        for f, t in enumerate(thetas):
            self.set_angle(f, t)

    # -- state --
    def finger(self, f: int) -> FwFinger:
        out = FwFinger()
        self.lib.fw_finger(f, ctypes.byref(out))
        return out

    def motor(self, f: int) -> FwMotor:
        out = FwMotor()
        self.lib.fw_motor(f, ctypes.byref(out))
        return out

    def status(self) -> FwStatus:
        out = FwStatus()
        self.lib.fw_status(ctypes.byref(out))
        return out

    def eeprom(self) -> ctypes.Array:
        size = self.lib.fw_eeprom_size()
        return (ctypes.c_uint8 * size).from_address(ctypes.addressof(self.lib.fw_eeprom().contents))

    # -- the link --
    def next_seq(self) -> int:
        self._seq = (self._seq + 1) % 0x80
        return self._seq

    def send_raw(self, data: bytes) -> None:
        n = self.lib.fw_rx(data, len(data))
        assert n == len(data), "the simulated receive buffer is full"

    def send_body(self, msg_id: int, body: bytes, seq: int | None = None) -> int:
        seq = self.next_seq() if seq is None else seq
        self.send_raw(encode_frame(seq, msg_id, body))
        return seq

    def send(self, msg: m.Message) -> int:
        return self.send_body(msg.ID, msg.encode())

    def _drain(self) -> None:
        buf = ctypes.create_string_buffer(8192)
        while True:
            n = self.lib.fw_tx(buf, len(buf))
            if n == 0:
                break
            for ev in self._decoder.feed(buf.raw[:n]):
                if isinstance(ev, Frame):
                    cls = m.BY_ID.get(ev.msg_id)
                    try:
                        msg = cls.decode(ev.body) if cls else None
                    except Exception:
                        msg = None
                    self.frames.append(Reply(ev.seq, msg, ev.msg_id, ev.body))
                else:
                    self.errors.append(ev)

    def take(self, kind: type[m.Message] | None = None) -> list[Reply]:
        """Remove and return the received frames (of one message type, if given)."""
        got = [r for r in self.frames if kind is None or r.msg_id == kind.ID]
        self.frames = [r for r in self.frames if r not in got]
        return got

    def request(self, msg: m.Message, *, ms: int = 2) -> Reply:
        """Send a request, run the board, and return the reply with its seq."""
        return self.request_body(msg.ID, msg.encode(), ms=ms)

    def request_body(self, msg_id: int, body: bytes, *, ms: int = 2) -> Reply:
        seq = self.send_body(msg_id, body)
        self.run(ms)
        replies = [r for r in self.frames if r.seq == seq]
        assert len(replies) == 1, f"expected one reply to seq {seq}, got {replies}"
        self.frames.remove(replies[0])
        return replies[0]

    def ok(self, msg: m.Message, *, ms: int = 2) -> m.Message:
        """A request that must succeed: its reply (ack or the named reply message)."""
        r = self.request(msg, ms=ms)
        assert r.msg is not None and not isinstance(r.msg, m.Nack), f"{msg.NAME}: {r.msg}"
        return r.msg

    def nack(self, msg_id: int, body: bytes) -> m.Nack:
        r = self.request_body(msg_id, body)
        assert isinstance(r.msg, m.Nack), f"expected a nack, got {r.msg}"
        return r.msg


def raw_body(cls: type[m.Message], *values: int | float) -> bytes:
    """A body packed from raw wire values, bypassing the host's range checks."""
    return cls._STRUCT.pack(*values)


def pack(fmt: str, *values: int | float) -> bytes:
    return struct.pack("<" + fmt, *values)


# ---- a simple finger plant for closed-loop tests --------------------------------------------


def motor_duty(drive: int, counts: int) -> float:
    """Signed duty (positive pulls) of one channel, as the driver sees it."""
    if drive == FORWARD:
        return counts / PWM_PERIOD
    if drive == REVERSE:
        return -counts / PWM_PERIOD
    return 0.0


@dataclass
class FingerPlant:
    """Joint-2 angle of a tendon finger under its net motor pull: a geared DC motor with
    Coulomb friction, θ'' = (w0 (u - friction sign) - θ') / tau, where u is the flexor's duty
    less the extensor's (antagonistic) or the motor's duty (rotary). An optional wall stops
    the finger (an object in a grasp, or a jam)."""

    w0: float = 6.0  # rad/s at full duty, no load
    tau: float = 0.03  # s, mechanical time constant
    friction: float = 0.03  # duty needed to move
    theta: float = 0.0
    omega: float = 0.0
    wall: float | None = None  # the finger cannot pass this angle (flexing)

    def advance(self, u: float, dt: float, substeps: int = 5) -> None:
        h = dt / substeps
        for _ in range(substeps):
            if self.omega == 0.0 and abs(u) <= self.friction:
                acc = 0.0
            else:
                direction = math.copysign(1.0, self.omega if self.omega != 0.0 else u)
                acc = (self.w0 * (u - self.friction * direction) - self.omega) / self.tau
            new_omega = self.omega + acc * h
            if self.omega != 0.0 and new_omega * self.omega < 0 and abs(u) <= self.friction:
                new_omega = 0.0  # friction stops it rather than reversing it
            self.omega = new_omega
            self.theta += self.omega * h
            if self.wall is not None and self.theta > self.wall:
                self.theta = self.wall
                self.omega = 0.0


class ClosedLoop:
    """The simulated board driving FingerPlants through its motor pins, sampled by its ADC."""

    def __init__(self, sim: Sim, plants: dict[int, FingerPlant]) -> None:
        self.sim = sim
        self.plants = plants
        for f, p in plants.items():
            sim.set_angle(f, p.theta)

    def net_duty(self, f: int) -> float:
        mo = self.sim.motor(f)
        if not mo.stby:
            return 0.0
        return motor_duty(mo.drive_a, mo.counts_a) - motor_duty(mo.drive_b, mo.counts_b)

    def run(self, ms: int, record: int | None = None) -> list[tuple[float, float, float]]:
        """Runs `ms` ticks; returns (t, θ, u) of finger `record` each tick."""
        trace = []
        for k in range(ms):
            for f, p in self.plants.items():
                u = self.net_duty(f)
                p.advance(u, 1e-3)
                self.sim.set_angle(f, p.theta)
                if f == record:
                    trace.append((k * 1e-3, p.theta, u))
            self.sim.lib.fw_tick(1)
            self.sim.lib.fw_loop(1)
        self.sim._drain()
        return trace


def step_response(sim: Sim, step: float, ms: int = 1500) -> list[tuple[float, float, float]]:
    """Finger 0 on a FingerPlant, in POSITION with the board's gains, from 0 to a target
    `step` rad: (t, θ, u) each tick (the host silent meanwhile, under a 10 s timeout)."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    loop = ClosedLoop(sim, {0: FingerPlant()})
    sim.ok(m.SetMode(mask=1, mode=(2, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1, value=(step, 0, 0, 0, 0)))
    return loop.run(ms, record=0)


def step_figures(trace: list[tuple[float, float, float]], step: float) -> dict[str, float]:
    """A positive step's rise (10-90 %), overshoot, settling time (into +-2 %) and its mean
    error over the last 200 ms."""
    t10 = next(t for t, x, _ in trace if x >= 0.1 * step)
    t90 = next(t for t, x, _ in trace if x >= 0.9 * step)
    peak = max(x for _, x, _ in trace)
    settle = max((t for t, x, _ in trace if abs(x - step) > 0.02 * step), default=0.0)
    final = sum(x for _, x, _ in trace[-200:]) / 200
    return {
        "rise_s": t90 - t10,
        "overshoot": max(0.0, (peak - step) / step),
        "settle_s": settle,
        "final_error_rad": final - step,
    }
