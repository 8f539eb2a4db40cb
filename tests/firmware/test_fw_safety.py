"""Every safety rule of the firmware, on the simulated board (host build of the core)."""

from __future__ import annotations

import ctypes

import pytest
from fwsim import BRAKE, COAST, FORWARD, ClosedLoop, FingerPlant, Sim, m

F = m.FaultBits
POSITION, DUTY, GRASP = 2, 3, 4


def set_mode(sim: Sim, finger: int, mode: int, duty: float = 0.0, effort: float = 0.0) -> None:
    modes, duties, efforts = [0] * 5, [0.0] * 5, [0.0] * 5
    modes[finger], duties[finger], efforts[finger] = mode, duty, effort
    sim.ok(
        m.SetMode(mask=1 << finger, mode=tuple(modes), duty=tuple(duties), effort=tuple(efforts))
    )


def set_target(sim: Sim, finger: int, theta2: float) -> None:
    values = [0.0] * 5
    values[finger] = theta2
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1 << finger, value=tuple(values)))


def motors_off(sim: Sim, finger: int) -> bool:
    mo = sim.motor(finger)
    return mo.drive_a == COAST and mo.drive_b == COAST and not mo.stby


def move_to(sim: Sim, finger: int, theta2: float, step: float = 0.05) -> None:
    """Walk a finger's encoder to theta2 a plausible step per tick (no ENCODER_JUMP)."""
    now = sim.finger(finger).theta_rad
    n = max(1, int(abs(theta2 - now) / step) + 1)
    for k in range(1, n + 1):
        sim.set_angle(finger, now + (theta2 - now) * k / n)
        sim.run(1)


def limits(sim: Sim, finger: int = 0, **changes: float) -> None:
    cur = sim.ok(m.GetLimits(finger=finger))
    fields = {f.name: getattr(cur, f.name) for f in m.SetLimits.FIELDS}
    fields.update(changes)
    sim.ok(m.SetLimits(**fields))


# ---- host silence ---------------------------------------------------------------------------


@pytest.mark.parametrize("action", [m.SafeAction.HOLD, m.SafeAction.COAST])
def test_host_silence_applies_the_safe_action_within_one_tick(sim: Sim, action) -> None:
    sim.ok(m.SetSafety(heartbeat_timeout=0.2, safe_action=action))
    move_to(sim, 1, 0.25)
    move_to(sim, 2, 0.1)
    set_mode(sim, 1, DUTY, duty=0.3)
    set_target(sim, 2, 0.4)
    set_mode(sim, 2, POSITION)
    # The last frame was taken in the loop pass just run; the next tick notes it.
    ticks = 0
    while sim.finger(1).faults == 0:
        sim.run(1)  # a tick, then a loop() pass (with nothing received)
        ticks += 1
        assert ticks <= 201
    assert ticks in (200, 201)  # the timeout is 200 ticks: acted on within one tick of it
    for f in (1, 2):
        fg = sim.finger(f)
        assert fg.faults == F.HOST_TIMEOUT
        if action == m.SafeAction.HOLD:
            assert fg.mode == POSITION
            assert abs(fg.target_rad - (0.25 if f == 1 else 0.1)) < 0.01
            assert sim.motor(f).stby
        else:
            assert fg.mode == 0
            assert motors_off(sim, f)
    # Idle fingers run nothing, so silence concerns them not.
    assert sim.finger(0).faults == 0
    reports = sim.take(m.Fault)
    assert {r.msg.finger for r in reports} == {1, 2}
    assert all(r.msg.new_faults == F.HOST_TIMEOUT for r in reports)


def test_any_valid_frame_feeds_the_host_watchdog(sim: Sim) -> None:
    sim.ok(m.SetSafety(heartbeat_timeout=0.1, safe_action=m.SafeAction.COAST))
    set_mode(sim, 0, POSITION)
    for _ in range(10):
        sim.run(80)
        sim.send(m.Ping(token=1))  # not a heartbeat, but a valid frame
    sim.run(5)
    assert sim.finger(0).faults == 0
    # A frame with a bad CRC does not count.
    sim.send_raw(b"\x05\x01\x02\x03\x04\x00")
    sim.run(120)
    assert sim.finger(0).faults == F.HOST_TIMEOUT


def test_goodbye_stands_the_silence_rule_down_until_the_next_frame(sim: Sim) -> None:
    sim.ok(m.SetSafety(heartbeat_timeout=0.1, safe_action=m.SafeAction.COAST))
    move_to(sim, 1, 0.2)
    set_target(sim, 1, 0.2)
    set_mode(sim, 1, POSITION)
    sim.ok(m.Goodbye())
    sim.ok(m.Goodbye())  # a second one is done again (its ack is not cached): nothing re-arms
    sim.run(500)  # five timeouts of silence
    assert sim.finger(1).faults == 0 and sim.finger(1).mode == POSITION  # still holding
    sim.send(m.Ping(token=1))  # a new host's first frame arms the rule again
    sim.run(150)
    assert sim.finger(1).faults == F.HOST_TIMEOUT and motors_off(sim, 1)


def test_a_silent_host_with_an_idle_hand_latches_nothing(sim: Sim) -> None:
    sim.run(2000)
    assert all(sim.finger(f).faults == 0 for f in range(5))


# ---- encoders -------------------------------------------------------------------------------


@pytest.mark.parametrize("adc", [0, 60, 950, 1023])
def test_encoder_out_of_band_turns_the_finger_off(sim: Sim, adc: int) -> None:
    set_mode(sim, 3, DUTY, duty=0.4)
    sim.run(20)
    assert sim.motor(3).drive_a == FORWARD and sim.motor(3).stby
    sim.set_adc(3, adc)
    sim.lib.fw_tick(1)  # one tick on the host; on the AVR the ADC round adds at most one more
    assert sim.finger(3).faults & F.ENCODER_RANGE
    assert motors_off(sim, 3)
    assert sim.finger(3).mode == 0


def test_encoder_band_edges_are_valid(sim: Sim) -> None:
    for adc in (103, 500, 921):  # 10 % .. 90 % of the ADC range: a valid reading
        sim.set_adc(0, adc)
        sim.lib.fw_tick(1)
        # (These jumps, and the angles at the band's edges, +-pi, are other faults.)
        assert sim.finger(0).faults & F.ENCODER_RANGE == 0


def test_encoder_jump_is_a_fault(sim: Sim) -> None:
    set_mode(sim, 0, POSITION)
    sim.set_angle(0, 0.10)
    sim.run(5)
    sim.set_angle(0, 0.25)  # 0.15 rad in one tick: plausible under the 0.2 rad default
    sim.lib.fw_tick(1)
    assert sim.finger(0).faults == 0
    sim.set_angle(0, 0.55)  # 0.3 rad in one tick
    sim.lib.fw_tick(1)
    assert sim.finger(0).faults & F.ENCODER_JUMP
    assert motors_off(sim, 0)


def test_a_stopped_sampler_is_an_encoder_fault(sim: Sim) -> None:
    set_mode(sim, 0, POSITION)
    sim.lib.fw_freeze_adc(1)
    sim.lib.fw_tick(2)
    assert sim.finger(0).faults == 0  # a late round or two is tolerated
    sim.lib.fw_tick(2)
    assert all(sim.finger(f).faults & F.ENCODER_RANGE for f in range(5))
    sim.lib.fw_freeze_adc(0)


# ---- stall and grasp ------------------------------------------------------------------------


def stall_setup(sim: Sim, mode: int, **kw: float) -> ClosedLoop:
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    limits(sim, stall_error=0.2, stall_motion=0.02, stall_time=0.5)
    loop = ClosedLoop(sim, {0: FingerPlant(wall=0.05)})
    if mode in (POSITION, GRASP):
        set_target(sim, 0, 1.0)
    set_mode(sim, 0, mode, **kw)
    return loop


@pytest.mark.parametrize("mode,kw", [(POSITION, {}), (DUTY, {"duty": 0.6})])
def test_stall_turns_the_motors_off(sim: Sim, mode: int, kw: dict) -> None:
    loop = stall_setup(sim, mode, **kw)
    loop.run(450)  # the output saturates within ~40 ms; the stall time is 500 ms
    assert sim.finger(0).faults == 0
    loop.run(150)
    assert sim.finger(0).faults == F.STALL
    assert motors_off(sim, 0)


def test_a_moving_finger_does_not_stall(sim: Sim) -> None:
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    limits(sim, stall_error=0.2, stall_motion=0.02, stall_time=0.05)
    loop = ClosedLoop(sim, {0: FingerPlant(w0=1.0)})  # slow, saturated, but moving
    set_target(sim, 0, 1.5)
    set_mode(sim, 0, POSITION)
    loop.run(1000)
    assert sim.finger(0).faults == 0


def test_grasp_holds_on_contact_within_its_effort(sim: Sim) -> None:
    loop = stall_setup(sim, GRASP, effort=0.4)
    loop.run(2000)
    fg = sim.finger(0)
    assert fg.faults == 0
    assert fg.contact
    assert fg.mode == GRASP
    mo = sim.motor(0)
    assert mo.drive_a == FORWARD and mo.stby
    assert mo.counts_a <= round(0.4 * 800) + 1  # the flexor's duty never exceeds the effort
    assert loop.net_duty(0) > 0.25  # and it keeps squeezing


# ---- joint limits ---------------------------------------------------------------------------


def test_joint_limit_latches_beyond_the_margin(sim: Sim) -> None:
    limits(sim, theta2_min=-1.0, theta2_max=1.0, limit_margin=0.1)
    set_mode(sim, 0, POSITION)
    move_to(sim, 0, 1.09)
    assert sim.finger(0).faults == 0
    sim.set_angle(0, 1.13)
    sim.run(1)
    assert sim.finger(0).faults == F.JOINT_LIMIT
    # Short brake, not coast (test_fw_limit_brake.py measures why): nothing driven, the
    # motors' terminals shorted.
    mo = sim.motor(0)
    assert sim.finger(0).mode == m.ControlMode.BRAKE
    assert (mo.drive_a, mo.drive_b, mo.counts_a, mo.counts_b, mo.stby) == (BRAKE, BRAKE, 0, 0, 1)
    # Another stop fault on top: nothing of the finger is trusted, the driver goes off.
    sim.set_adc(0, 5)
    sim.run(1)
    assert motors_off(sim, 0)


def test_duty_mode_never_drives_past_a_limit(sim: Sim) -> None:
    sim.ok(
        m.SetGains(
            finger=0,
            kp=3.0,
            ki=2.0,
            kd=0.05,
            d_cutoff_hz=30.0,
            deadband_duty=0.0,
            slew_per_s=1000.0,
            max_duty=0.8,
            pretension_duty=0.0,
        )
    )
    limits(sim, theta2_min=-1.0, theta2_max=1.0, limit_margin=0.1)
    move_to(sim, 0, 1.02)
    set_mode(sim, 0, DUTY, duty=0.5)
    sim.run(3)
    assert sim.finger(0).output == 0  # flexing further is cut
    set_mode(sim, 0, DUTY, duty=-0.5)
    sim.run(3)
    assert sim.finger(0).output < 0  # away from the limit is allowed


def test_targets_beyond_the_limits_are_refused(sim: Sim) -> None:
    limits(sim, finger=2, theta2_min=-0.5, theta2_max=0.8)
    set_target(sim, 2, 0.5)
    r = sim.request(
        m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=0b101, value=(0.1, 0, 0.85, 0, 0))
    )
    assert isinstance(r.msg, m.Nack)
    assert (r.msg.code, r.msg.detail) == (m.ErrorCode.OUT_OF_RANGE, 0x80 | 2)
    assert abs(sim.finger(2).target_rad - 0.5) < 1e-3  # nothing changed, finger 0 neither
    assert abs(sim.finger(0).target_rad) < 1e-3


# ---- overrun, latching, outputs of a faulted finger -------------------------------------------


def test_tick_overrun_stops_every_finger(sim: Sim) -> None:
    for f in range(5):
        set_mode(sim, f, POSITION)
    sim.lib.fw_set_period_elapsed(1)
    sim.lib.fw_tick(1)
    sim.lib.fw_set_period_elapsed(0)
    sim.lib.fw_tick(1)
    for f in range(5):
        assert sim.finger(f).faults == F.OVERRUN
        assert motors_off(sim, f)
    stats = sim.ok(m.GetStats())
    assert stats.tick_overruns == 1


def test_faults_stay_latched_until_cleared(sim: Sim) -> None:
    set_mode(sim, 0, POSITION)
    sim.set_adc(0, 10)
    sim.run(2)
    sim.set_angle(0, 0.0)  # the cause is gone ...
    sim.run(50)
    assert sim.finger(0).faults == F.ENCODER_RANGE  # ... the fault is not
    nack = sim.nack(
        m.SetMode.ID,
        m.SetMode(mask=1, mode=(POSITION, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5).encode(),
    )
    assert (nack.code, nack.detail) == (m.ErrorCode.FAULTED, 0)
    sim.ok(m.ClearFaults(mask=1))
    assert sim.finger(0).faults == 0
    assert sim.finger(0).mode == 0  # the host sets a mode again
    set_mode(sim, 0, POSITION)
    # A cause that persists latches again at the next tick.
    sim.set_adc(0, 10)
    sim.ok(m.ClearFaults(mask=1))
    assert sim.finger(0).faults == F.ENCODER_RANGE


def test_brake_and_coast_follow_the_truth_table(sim: Sim) -> None:
    sim.ok(m.SetMode(mask=0b11, mode=(1, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    sim.run(2)
    braked, coasting = sim.motor(0), sim.motor(1)
    assert (braked.drive_a, braked.drive_b, braked.stby) == (BRAKE, BRAKE, 1)
    assert (coasting.drive_a, coasting.drive_b, coasting.stby) == (COAST, COAST, 0)
    # A fault takes a braking finger off too: STBY low.
    sim.set_adc(0, 5)
    sim.run(1)
    assert motors_off(sim, 0)


def test_zero_duty_is_really_off(sim: Sim) -> None:
    sim.ok(
        m.SetGains(
            finger=0,
            kp=3.0,
            ki=2.0,
            kd=0.05,
            d_cutoff_hz=30.0,
            deadband_duty=0.0,
            slew_per_s=1000.0,
            max_duty=0.8,
            pretension_duty=0.0,
        )
    )
    set_mode(sim, 0, DUTY, duty=0.0)
    sim.run(3)
    mo = sim.motor(0)
    assert (mo.drive_a, mo.counts_a, mo.drive_b, mo.counts_b) == (COAST, 0, COAST, 0)
    # The host layer also checks every write: no driving channel with zero counts, ever.
    assert sim.status().lock_errors == 0


# ---- the watchdog and the reset cause ---------------------------------------------------------


def test_watchdog_is_fed_while_loop_and_tick_run(sim: Sim) -> None:
    st = sim.status()
    assert st.wdt_started
    before = st.wdt_feeds
    sim.run(100)
    assert sim.status().wdt_feeds >= before + 100


def test_a_hung_loop_stops_the_motors_and_is_reported_after_the_reset(sim: Sim) -> None:
    set_mode(sim, 0, DUTY, duty=0.5)
    sim.run(5)
    assert sim.motor(0).stby
    sim.lib.fw_tick(60)  # the tick runs, loop() does not
    st = sim.status()
    assert st.halted and st.hang_mark
    assert all(motors_off(sim, f) for f in range(5))
    feeds = st.wdt_feeds
    sim.loop(5)  # loop() comes back too late: the board no longer feeds the watchdog
    assert sim.status().wdt_feeds == feeds
    sim.power_on(reset_cause=m.ResetCause.UNKNOWN)  # the bootloader cleared MCUSR
    boot = sim.take(m.Boot)[0].msg
    assert boot.reset_cause == m.ResetCause.WATCHDOG
    assert sim.ok(m.Identify()).reset_cause == m.ResetCause.WATCHDOG
    assert not sim.status().hang_mark


def assert_halted_and_says_so(sim: Sim) -> None:
    """Halted: the state says what the motors do (every finger COAST, no duty) and drive
    requests are refused as HALTED; the rest is still answered."""
    for f in range(5):
        assert sim.finger(f).mode == m.ControlMode.COAST
        assert (sim.finger(f).duty_a, sim.finger(f).duty_b) == (0, 0)
        assert motors_off(sim, f)
    st = sim.ok(m.GetState())
    assert all(d == 0 for d in st.duty_a + st.duty_b)
    assert all(mode == m.ControlMode.COAST for mode in sim.ok(m.GetStatus()).mode)
    zeros = (0,) * 5
    drive = [
        m.SetMode(mask=1, mode=(m.ControlMode.POSITION, 0, 0, 0, 0), duty=zeros, effort=zeros),
        m.SetMode(mask=1, mode=(m.ControlMode.BRAKE, 0, 0, 0, 0), duty=zeros, effort=zeros),
        m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1, value=(0.3, 0, 0, 0, 0)),
    ]
    for req in drive:
        nack = sim.nack(req.ID, req.encode())
        assert (nack.code, nack.detail) == (m.ErrorCode.HALTED, 0)
    assert sim.finger(0).mode == m.ControlMode.COAST and motors_off(sim, 0)
    sim.ok(m.Identify())


def test_the_loop_alive_rule_allows_20_ticks(sim: Sim) -> None:
    """Below the watchdog's 30 ms, so the firmware stops the motors itself first."""
    set_mode(sim, 0, DUTY, duty=0.5)
    sim.run(5)
    sim.lib.fw_tick(20)  # (the first tick after loop() still sees it run)
    assert not sim.status().halted and sim.motor(0).stby
    sim.lib.fw_tick(2)
    assert sim.status().halted and motors_off(sim, 0)


def test_a_halted_hand_reports_coast_and_refuses_to_drive(sim: Sim) -> None:
    """issue 13: once halted, state kept reporting the last mode and duties (GRASP, 10 % on
    both motors) while every motor was off, and set_* were accepted."""
    set_mode(sim, 0, m.ControlMode.GRASP, effort=0.6)
    set_mode(sim, 1, DUTY, duty=0.5)
    sim.run(5)
    assert sim.finger(0).duty_a != 0
    sim.lib.fw_tick(60)  # the tick runs, loop() does not: the loop-alive rule halts the hand
    assert sim.status().halted
    assert_halted_and_says_so(sim)


def test_a_stopped_tick_halts_the_hand_too(sim: Sim) -> None:
    set_mode(sim, 0, DUTY, duty=0.5)
    sim.run(5)
    sim.lib.fw_advance_ms(30)  # time passes, no tick comes
    sim.loop(1)
    assert sim.status().halted
    assert_halted_and_says_so(sim)


def test_a_stopped_tick_stops_the_motors(sim: Sim) -> None:
    set_mode(sim, 0, DUTY, duty=0.5)
    sim.run(5)
    feeds = sim.status().wdt_feeds
    sim.lib.fw_advance_ms(30)  # time passes, no tick comes
    sim.loop(1)
    st = sim.status()
    assert st.all_off_calls > 0 and st.hang_mark
    assert st.wdt_feeds == feeds


@pytest.mark.parametrize("cause", list(m.ResetCause))
def test_reset_cause_is_reported(sim: Sim, cause: m.ResetCause) -> None:
    sim.power_on(reset_cause=int(cause))
    assert sim.take(m.Boot)[0].msg.reset_cause == cause
    assert sim.ok(m.Identify()).reset_cause == cause


def test_brake_asked_of_a_faulted_finger_keeps_its_driver_off(sim: Sim) -> None:
    """BRAKE is not refused on a finger with a stop fault (it drives nothing), but its STBY
    stays low: no motor is driven, shorted included, once a stop fault latched. (issue 13:
    letting BRAKE raise STBY there passed every test.)"""
    sim.set_adc(0, 5)  # unplugged: ENCODER_RANGE latches
    sim.run(2)
    sim.set_angle(0, 0.0)  # plugged back: the cause is gone, the fault stays latched
    sim.run(2)
    assert sim.finger(0).faults == F.ENCODER_RANGE
    sim.ok(m.SetMode(mask=0b11, mode=(BRAKE, BRAKE, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    sim.run(3)
    assert sim.finger(0).mode == BRAKE
    faulted, healthy = sim.motor(0), sim.motor(1)
    assert not faulted.stby and (faulted.counts_a, faulted.counts_b) == (0, 0)
    assert (healthy.drive_a, healthy.drive_b, healthy.stby) == (BRAKE, BRAKE, 1)


def safe_action_run(sim: Sim, general: bool) -> list[tuple]:
    """Fingers in DUTY, POSITION away from its target and GRASP, their encoders moving every
    tick, then silence: each tick's finger states and driver commands from two ticks before
    the timeout to 20 after, with the host-silence tick on its fast path or its general one."""
    sim.lib.fw_safe_action_general_path(1 if general else 0)
    sim.ok(m.SetSafety(heartbeat_timeout=0.05, safe_action=m.SafeAction.HOLD))
    for f, a in ((1, 0.2), (2, 0.1), (3, 0.3)):
        move_to(sim, f, a)
    set_mode(sim, 1, DUTY, duty=0.3)
    set_target(sim, 2, 0.4)
    set_mode(sim, 2, POSITION)
    set_mode(sim, 3, GRASP, effort=0.5)
    seen = []
    for k in range(70):
        sim.set_angles([0.0, 0.2 + 0.002 * k, 0.1 + 0.003 * k, 0.3 - 0.001 * k, 0.0])
        sim.run(1)
        fgs = [sim.finger(f) for f in range(5)]
        if fgs[1].faults or seen:
            seen.append(
                [(g.mode, g.faults, g.target, g.output, g.duty_a, g.duty_b) for g in fgs]
                + [(sim.motor(f).counts_a, sim.motor(f).counts_b) for f in range(5)]
            )
    sim.lib.fw_safe_action_general_path(0)
    return seen


def test_the_silence_ticks_fast_path_holds_as_its_general_twin(fwlib) -> None:
    """The host-silence tick's fast path (no law step after hold_here(): at zero error it
    gives the present output) against its general twin (hold_here() and the law's step), on
    the same inputs: the same modes, faults and held angles, and the same outputs within a
    count of the deadband's inverse."""
    runs = []
    for general in (False, True):
        sim = Sim(fwlib)
        ctypes.memset(sim.eeprom(), 0xFF, len(sim.eeprom()))  # blank: the default gains
        sim.power_on()
        runs.append(safe_action_run(sim, general))
    fast, general = runs
    assert len(fast) == len(general) >= 15
    assert fast[0][1][1] == F.HOST_TIMEOUT and fast[0][1][0] == POSITION  # DUTY went to HOLD
    for a, b in zip(fast, general, strict=True):
        for fa, fb in zip(a[:5], b[:5], strict=True):
            assert fa[:3] == fb[:3]  # mode, faults, target
            assert all(abs(x - y) <= 2 for x, y in zip(fa[3:], fb[3:], strict=True)), (fa, fb)
        for ma, mb in zip(a[5:], b[5:], strict=True):
            assert all(abs(x - y) <= 1 for x, y in zip(ma, mb, strict=True)), (ma, mb)
