"""Moves on the board's clock (core/path.h): the path's shape tick by tick, the stretching
rule, the feedforward, what ends a path, and what a move refuses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fwsim import BU, ClosedLoop, FingerPlant, Sim, m

POSITION = m.ControlMode.POSITION
DEFAULT = {"max_speed": 1.2, "max_accel": 8.0, "kv": 0.38, "ka": 0.0038}


def s(tau: np.ndarray) -> np.ndarray:
    t = np.clip(tau, 0.0, 1.0)
    return t**3 * (10 - 15 * t + 6 * t * t)


def ds(tau: np.ndarray) -> np.ndarray:
    t = np.clip(tau, 0.0, 1.0)
    return 30 * t * t * (1 - t) ** 2


def dds(tau: np.ndarray) -> np.ndarray:
    t = np.clip(tau, 0.0, 1.0)
    return 60 * t * (1 - t) * (1 - 2 * t)


def move(f: int, value: float, duration: float, move_id: int = 1) -> m.Move:
    values = [0.0] * 5
    durations = [0.0] * 5
    values[f], durations[f] = value, duration
    return m.Move(
        move_id=move_id,
        kind=m.TargetKind.JOINT2_ANGLE,
        mask=1 << f,
        value=tuple(values),
        duration=tuple(durations),
    )


def position(sim: Sim, mask: int) -> None:
    modes = tuple(POSITION if mask & (1 << i) else 0 for i in range(5))
    sim.ok(m.SetMode(mask=mask, mode=modes, duty=(0,) * 5, effort=(0,) * 5))


@pytest.fixture
def held(sim: Sim) -> Sim:
    """Finger 1 in POSITION at 0 rad, the host's silence allowed for 10 s."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    position(sim, 0b10)
    return sim


def test_the_setpoint_follows_the_minimum_jerk_path_tick_by_tick(held: Sim) -> None:
    sim = held
    # The encoder held where the finger is would make the PID push toward a stall; the
    # setpoint alone is looked at here, so the stall rule is given a long time.
    sim.ok(m.SetLimits(1, -1.6, 1.6, 0.1, 3.0, 0.02, 10.0, 0.2))
    reply = sim.ok(move(1, 0.3, 0.5))
    assert isinstance(reply, m.Moving)
    assert reply.duration[1] == pytest.approx(0.5) and reply.stretched == 0
    assert reply.duration[0] == 0 and reply.move_id == 1
    done = 500 - sim.lib.fw_path_left(1)  # ticks run since the move started
    targets = []
    for _ in range(520):
        sim.tick(1)
        sim.loop(1)
        targets.append(sim.finger(1).target * BU)
    got = np.array(targets)
    want = 0.3 * s((np.arange(1, 521) + done) / 500.0)
    # within 3 counts of the curve at every tick (evaluated every 5 ms, straight between)
    assert np.max(np.abs(got - want)) < 3 * BU
    assert targets[499 - done] == pytest.approx(0.3, abs=BU / 2)  # there on the last tick
    assert np.all(np.diff(got) >= 0)  # no overshoot, no step back
    assert sim.lib.fw_path_left(1) == 0


@pytest.mark.parametrize(
    "distance,duration,expected,stretched",
    [
        (1.0, 0.2, 1.875 * 1.0 / 1.2, True),  # speed-limited
        (1.0, 0.0, 1.875 * 1.0 / 1.2, False),  # "as fast as allowed" is no stretch
        (0.05, 0.1, math.sqrt(5.7735 * 0.05 / 8.0), True),  # acceleration-limited
        (0.3, 1.0, 1.0, False),  # within the limits: as asked
        (-1.0, 0.2, 1.875 * 1.0 / 1.2, True),  # either way
    ],
)
def test_a_path_too_fast_for_the_limits_is_stretched_and_says_so(
    held: Sim, distance: float, duration: float, expected: float, stretched: bool
) -> None:
    reply = held.ok(move(1, distance, duration))
    # whole ticks, rounded up; the end quantised to a count (1.9e-4 rad) moves T by a tick
    assert expected <= reply.duration[1] + 1e-3 < expected + 2.5e-3
    assert bool(reply.stretched & 0b10) == stretched
    assert held.lib.fw_path_left(1) == pytest.approx(reply.duration[1] * 1000, abs=3)


def test_the_limits_are_the_fingers_own(held: Sim) -> None:
    held.ok(m.SetMotion(finger=1, max_speed=100.0, max_accel=2.0, kv=0.38, ka=0.0038))
    reply = held.ok(move(1, 1.0, 0.2))
    assert reply.duration[1] == pytest.approx(math.sqrt(5.7735 / 2.0), abs=1e-3)
    other = held.ok(m.GetMotion(finger=0))  # the other fingers keep the defaults
    assert {k: getattr(other, k) for k in DEFAULT} == pytest.approx(DEFAULT)


def test_the_feedforward_is_kv_speed_plus_ka_acceleration(held: Sim) -> None:
    sim = held
    kv, ka, distance, duration = 0.4, 0.05, 0.8, 0.8
    sim.ok(m.SetMotion(finger=1, max_speed=10.0, max_accel=100.0, kv=kv, ka=ka))
    sim.ok(m.SetLimits(1, -1.6, 1.6, 0.1, 3.0, 0.02, 10.0, 0.2))
    sim.ok(move(1, distance, duration))
    ff = []
    for _ in range(800):
        sim.tick(1)
        sim.loop(1)
        ff.append(sim.lib.fw_path_ff(1) / 32768.0)
    got = np.array(ff)
    k = np.arange(800)
    # each segment's feedforward is its end point's (5 ticks ahead at most), held for its 5
    # ticks: compare within that window
    want = [
        kv * distance * ds(np.arange(i, i + 7) / 800) / duration
        + ka * distance * dds(np.arange(i, i + 7) / 800) / duration**2
        for i in k
    ]
    lo = np.array([w.min() for w in want]) - 2e-3
    hi = np.array([w.max() for w in want]) + 2e-3
    inside = (got >= lo) & (got <= hi)
    assert inside[10:-6].all(), np.flatnonzero(~inside)[:10]
    tau = np.linspace(0, 1, 10001)
    peak = np.max(kv * distance * ds(tau) / duration + ka * distance * dds(tau) / duration**2)
    assert got.max() == pytest.approx(peak, rel=0.02)
    assert got.min() < -0.01  # the deceleration's share, near the end
    assert got[-1] == 0.0  # at rest at the end


def test_moves_track_a_plant_with_its_constants_as_feedforward(held: Sim) -> None:
    """The tests' reference plant (6 rad/s at full duty, 30 ms, friction 0.03): with its
    constants as the feedforward gains (kv = 1/6 per rad/s, ka = 0.03/6 per rad/s^2), the
    finger stays within the tracking goal's 3 degrees of the setpoint the whole move (its
    Coulomb friction, which the feedforward leaves to the PID, is most of what is left);
    without them it trails by four times as much."""

    def worst(kv: float, ka: float) -> float:
        sim = held
        sim.power_on()
        sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
        loop = ClosedLoop(sim, {1: FingerPlant()})
        position(sim, 0b10)
        sim.ok(m.SetMotion(finger=1, max_speed=3.0, max_accel=30.0, kv=kv, ka=ka))
        sim.ok(move(1, 1.0, 0.8))
        err = []
        for _ in range(900):
            loop.run(1)
            err.append(abs(sim.finger(1).theta - sim.finger(1).target) * BU)
        assert sim.finger(1).target * BU == pytest.approx(1.0, abs=BU)
        return max(err)

    with_ff = worst(1 / 6, 0.03 / 6)
    without = worst(0.0, 0.0)
    assert with_ff < math.radians(2.5)
    assert without > 4 * with_ff


def test_a_resent_move_changes_nothing_and_gets_the_same_reply(held: Sim) -> None:
    sim = held
    body = move(1, 0.5, 0.4, move_id=7).encode()
    seq = sim.send_body(m.Move.ID, body)
    sim.run(100)
    (first,) = sim.take(m.Moving)
    left = sim.lib.fw_path_left(1)
    sim.send_body(m.Move.ID, body, seq=seq)  # the same frame again: a resend
    sim.run(2)
    (again,) = sim.take(m.Moving)
    assert again.body == first.body and again.seq == seq
    assert sim.lib.fw_path_left(1) == left - 2  # the path went on: not restarted
    # the same bytes under a new seq are a new move: it starts again from the setpoint
    sim.send_body(m.Move.ID, body)
    sim.run(1)
    assert sim.lib.fw_path_left(1) > left


def test_set_targets_a_mode_change_or_a_fault_ends_the_path(held: Sim) -> None:
    sim = held
    sim.ok(move(1, 1.0, 1.0))
    sim.run(300)
    assert sim.lib.fw_path_left(1) > 0
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=0b10, value=(0, 0.2, 0, 0, 0)))
    assert sim.lib.fw_path_left(1) == 0
    sim.run(5)
    assert sim.finger(1).target * BU == pytest.approx(0.2, abs=BU)
    sim.ok(move(1, 1.0, 1.0))
    sim.run(10)
    sim.ok(m.SetMode(mask=0b10, mode=(0, 1, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    assert sim.lib.fw_path_left(1) == 0
    position(sim, 0b10)
    sim.ok(move(1, 1.0, 1.0))
    sim.run(10)
    sim.set_adc(1, 0)  # unplugged: ENCODER_RANGE stops the finger, and its path
    sim.run(3)
    assert sim.finger(1).faults & m.FaultBits.ENCODER_RANGE
    assert sim.lib.fw_path_left(1) == 0


def test_a_move_is_refused_for_a_finger_not_in_closed_loop_and_changes_nothing(
    held: Sim,
) -> None:
    sim = held
    two = m.Move(
        move_id=3,
        kind=m.TargetKind.JOINT2_ANGLE,
        mask=0b110,
        value=(0, 0.5, 0.5, 0, 0),
        duration=(0, 1.0, 1.0, 0, 0),
    )
    nack = sim.request(two).msg
    assert (nack.code, nack.detail) == (m.ErrorCode.BUSY, 2)  # finger 2 is in COAST
    assert sim.lib.fw_path_left(1) == 0  # finger 1's path did not start either
    over = move(1, 2.0, 1.0)
    nack = sim.request(over).msg
    assert (nack.code, nack.detail) == (m.ErrorCode.OUT_OF_RANGE, 0x81)
    flex = m.Move(
        move_id=4,
        kind=m.TargetKind.FLEXION,
        mask=0b10,
        value=(0, 1.5, 0, 0, 0),
        duration=(0, 1.0, 0, 0, 0),
    )
    assert sim.request(flex).msg.code == m.ErrorCode.OUT_OF_RANGE
    sim.set_adc(1, 0)
    sim.run(3)
    nack = sim.request(move(1, 0.5, 1.0, move_id=5)).msg
    assert (nack.code, nack.detail) == (m.ErrorCode.FAULTED, 1)


def test_a_move_in_flexion_ends_where_set_targets_would(held: Sim) -> None:
    sim = held
    flex = m.Move(
        move_id=9,
        kind=m.TargetKind.FLEXION,
        mask=0b10,
        value=(0, 0.5, 0, 0, 0),
        duration=(0, 0.0, 0, 0, 0),
    )
    reply = sim.ok(flex)
    sim.ok(m.SetLimits(1, -1.6, 1.6, 0.1, 3.0, 0.02, 10.0, 0.2))
    sim.run(int(reply.duration[1] * 1000) + 2)
    end = sim.finger(1).target
    sim.ok(m.SetTargets(kind=m.TargetKind.FLEXION, mask=0b10, value=(0, 0.5, 0, 0, 0)))
    assert sim.finger(1).target == end
