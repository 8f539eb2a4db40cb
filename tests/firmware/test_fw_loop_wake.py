"""Which ticks wake loop() (app::tick_done(), firmware/README.md, "Which ticks wake loop()"):
the host build run as the MEGA runs it, loop() only after a tick that asks for a pass, and the
safety rules that live in loop() keeping their timings."""

from __future__ import annotations

from itertools import pairwise

import pytest
from fwsim import Sim, m

F = m.FaultBits
POSITION, DUTY = 2, 3
EVERY = 5  # app::kLoopEveryTicks


def set_modes(sim: Sim, mask: int, mode: int, duty: float = 0.0) -> None:
    modes = tuple(mode if mask & (1 << f) else 0 for f in range(5))
    duties = tuple(duty if mask & (1 << f) else 0.0 for f in range(5))
    sim.ok(m.SetMode(mask=mask, mode=modes, duty=duties, effort=(0.0,) * 5))


def asked(woke: list[bool]) -> list[int]:
    return [i for i, w in enumerate(woke) if w]


def after_a_pass(sim: Sim) -> None:
    """Ticks run until one asks for a pass: the next EVERY - 1 ask for none of their own."""
    for _ in range(EVERY):
        if sim.run_woken(1)[0] == [True]:
            return
    raise AssertionError(f"no pass in {EVERY} ticks")


@pytest.fixture
def still(sim: Sim) -> Sim:
    """Five fingers in POSITION where their encoders stand, the host's silence allowed 10 s."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    set_modes(sim, 0b11111, POSITION)
    sim.run_woken(20)  # whatever the requests left to do
    return sim


def test_with_nothing_to_do_a_pass_comes_every_fifth_tick_and_keeps_the_hand_going(
    still: Sim,
) -> None:
    feeds = still.status().wdt_feeds
    woke, passes = still.run_woken(200)
    ticks = asked(woke)
    assert len(ticks) == 200 // EVERY
    assert {b - a for a, b in pairwise(ticks)} == {EVERY}
    assert passes == len(ticks)  # one pass each: nothing kept it awake
    st = still.status()
    assert not st.halted  # the loop-alive rule (20 ticks) is satisfied
    assert st.wdt_feeds - feeds == passes
    assert all(still.finger(f).mode == POSITION for f in range(5))


def test_each_stream_sample_asks_for_its_pass_and_the_fifth_tick_counts_from_it(
    still: Sim,
) -> None:
    still.ok(m.SetTelemetry(rate_hz=100))
    still.run_woken(30)
    still.take()
    woke, _ = still.run_woken(1000)
    ticks = asked(woke)
    gaps = {b - a for a, b in pairwise(ticks)}
    assert gaps == {EVERY}  # each sample's pass restarts the count: 200 passes, not 300
    assert len(still.take(m.State)) == 100  # every sample sent


def test_a_fault_the_tick_latches_is_reported_after_that_tick(still: Sim) -> None:
    after_a_pass(still)
    still.take()
    still.set_adc(3, 10)  # finger 3's encoder out of its band: ENCODER_RANGE in the next tick
    woke, _ = still.run_woken(1)
    assert woke == [True]
    assert still.finger(3).faults & F.ENCODER_RANGE
    (fault,) = still.take(m.Fault)
    assert fault.msg.finger == 3 and fault.msg.new_faults & F.ENCODER_RANGE


def test_a_move_asks_for_a_pass_every_tick_while_it_has_segments_to_plan(still: Sim) -> None:
    reply = still.ok(
        m.Move(
            move_id=1,
            kind=m.TargetKind.JOINT2_ANGLE,
            mask=0b10,
            value=(0.0, 0.2, 0.0, 0.0, 0.0),
            duration=(0.0, 0.1, 0.0, 0.0, 0.0),
        ),
    )
    assert isinstance(reply, m.Moving)
    ticks = round(reply.duration[1] * 1000)  # stretched to the finger's speed limits
    woke, _ = still.run_woken(ticks - 20)  # planned a segment ahead: done some ticks early
    assert all(woke)
    still.run_woken(40)
    woke, _ = still.run_woken(100)  # the move over: every fifth tick again
    assert len(asked(woke)) == 100 // EVERY
    assert abs(still.finger(1).target_rad - 0.2) < 1e-3


def first_stall_tick(sim: Sim, woken: bool) -> int:
    for t in range(1, 1000):
        if woken:
            sim.run_woken(1)
        else:
            sim.run(1)
        if sim.finger(0).faults & F.STALL:
            return t
    raise AssertionError("no stall in 1 s")


def test_the_stall_rule_stops_the_motor_within_the_ticks_of_a_pass_every_tick(sim: Sim) -> None:
    """The stall rule counts the ticks since each check, so checked every fifth tick it
    latches at most 4 ticks after a loop() that runs every tick (the host's sim.run)."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    set_modes(sim, 0b1, DUTY, duty=0.5)  # pushing, the encoder still: a stall
    every_tick = first_stall_tick(sim, woken=False)
    sim.power_on()
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    set_modes(sim, 0b1, DUTY, duty=0.5)
    woken = first_stall_tick(sim, woken=True)
    assert every_tick <= woken <= every_tick + EVERY - 1
    assert sim.motor(0).stby == 0  # off in the check's pass
    assert any(r.msg.new_faults & F.STALL for r in sim.take(m.Fault))


def test_the_tick_alive_rule_counts_from_the_last_tick_not_the_last_pass(still: Sim) -> None:
    after_a_pass(still)
    woke, _ = still.run_woken(EVERY - 2)  # the last pass some ticks before the last tick
    assert not any(woke)
    still.lib.fw_advance_ms(20)  # 20 ms without a tick: not yet "more than 20"
    still.loop(1)
    assert not still.status().halted
    still.lib.fw_advance_ms(1)
    still.loop(1)
    assert still.status().halted
