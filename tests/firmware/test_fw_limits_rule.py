"""The limits rule holds for every setpoint, a running move's included (issue 23): new limits
(set_limits, or any finger configuration applied) end a path that would leave them and clamp
the setpoint in, so no tick's setpoint lies beyond a limit in force."""

from __future__ import annotations

import pytest
from fwsim import BU, Sim, m

POSITION = m.ControlMode.POSITION
# Finger 1's defaults but for a long stall time (the encoder stands still while the setpoint
# moves, which would otherwise read as a stall) and theta2_max.
LIMITS = dict(
    finger=1,
    theta2_min=-1.6,
    limit_margin=0.1,
    stall_error=3.0,
    stall_motion=0.02,
    stall_time=10.0,
    encoder_jump=0.2,
)


def limits(theta2_max: float) -> m.SetLimits:
    return m.SetLimits(theta2_max=theta2_max, **LIMITS)  # type: ignore[arg-type]


def move(value: float, duration: float) -> m.Move:
    return m.Move(
        move_id=1,
        kind=m.TargetKind.JOINT2_ANGLE,
        mask=0b10,
        value=(0.0, value, 0.0, 0.0, 0.0),
        duration=(0.0, duration, 0.0, 0.0, 0.0),
    )


@pytest.fixture
def moving(sim: Sim) -> Sim:
    """Finger 1 in POSITION, 300 ms into a move to 0.8 rad (1.25 s: the speed limit's)."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    sim.ok(limits(1.6))
    sim.ok(m.SetMode(mask=0b10, mode=(0, POSITION, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    body = move(0.8, 1.0).encode()
    sim.move_seq = sim.send_body(m.Move.ID, body)  # type: ignore[attr-defined]
    sim.run(300)
    assert len(sim.take(m.Moving)) == 1 and sim.lib.fw_path_left(1) > 0
    return sim


def setpoints(sim: Sim, ms: int) -> list[float]:
    out = []
    for _ in range(ms):
        sim.run(1)
        out.append(sim.finger(1).target * BU)
    return out


def test_set_limits_during_a_move_keeps_every_later_setpoint_within_them(moving: Sim) -> None:
    """The fuzzing find of issue 23: a move to 0.8 rad, then theta2_max 0.3 rad 300 ms in
    (acked): the path's setpoint used to run on to 0.8 rad."""
    sim = moving
    assert sim.finger(1).target * BU < 0.3  # the path has not reached the new limit yet
    sim.ok(limits(0.3))
    got = setpoints(sim, 1000)
    assert max(got) <= 0.3 + BU / 2
    assert sim.lib.fw_path_left(1) == 0  # the path was ended: it would have left the limits
    assert got[-1] == got[0]  # held where the path had it


def test_a_setpoint_beyond_the_new_limits_is_clamped_in_at_once(moving: Sim) -> None:
    sim = moving
    assert sim.finger(1).target * BU > 0.05
    sim.ok(limits(0.05))
    assert sim.lib.fw_path_left(1) == 0
    assert max(setpoints(sim, 200)) == pytest.approx(0.05, abs=BU)


def test_new_limits_that_hold_the_rest_of_the_path_leave_it_running(moving: Sim) -> None:
    sim = moving
    left = sim.lib.fw_path_left(1)
    sim.ok(limits(1.0))
    assert sim.lib.fw_path_left(1) > 0 and sim.lib.fw_path_left(1) <= left
    got = setpoints(sim, 1000)
    assert got[-1] == pytest.approx(0.8, abs=BU)  # the move ends where it was asked to


def test_a_resent_move_after_its_path_was_ended_is_checked_anew(moving: Sim) -> None:
    """The move's memo goes with its path: its resend (same seq, same bytes) is not answered
    `moving` from the memo while no path runs, but checked against the limits in force."""
    sim = moving
    sim.ok(limits(0.3))
    sim.send_body(m.Move.ID, move(0.8, 1.0).encode(), seq=sim.move_seq)  # type: ignore[attr-defined]
    sim.run(2)
    (reply,) = [r for r in sim.frames if r.seq == sim.move_seq]  # type: ignore[attr-defined]
    assert isinstance(reply.msg, m.Nack) and reply.msg.code == m.ErrorCode.OUT_OF_RANGE
    assert sim.lib.fw_path_left(1) == 0
