"""Every safety rule of the firmware, triggered by fault injection on the emulated board and
seen by the Hand in the telemetry (the board's ``fault`` message and the state stream), with
the effect checked where it matters: on the driver pins and in the plant."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import FingerFaultError, Hand, HandState, TargetError
from utrf.protocol import messages as M
from utrf.protocol.errors import BoardResetError, NackError

F = M.FaultBits


def silent(hand: Hand, seconds: float) -> None:
    """The host falls silent: simulated time passes with no frame sent (no heartbeats)."""
    period, hand.link.heartbeat_period_s = hand.link.heartbeat_period_s, None
    try:
        hand.clock.sleep(seconds)
    finally:
        hand.link.heartbeat_period_s = period


def streamed(hand: Hand) -> HandState:
    """The latest sample of the telemetry stream (not a get_state reply)."""
    hand.clock.sleep(0.03)
    st = hand.latest
    assert st is not None and st.seq is not None and st.seq >= M.BOARD_SEQ_FLAG
    return st


def new_faults(hand: Hand, finger: str) -> F:
    bits = F(0)
    for e in hand.faults_seen:
        if e.finger == finger:
            bits |= e.new_faults
    return bits


def motors_off(board: EmulatedBoard, finger: int) -> bool:
    pins = board.pins
    return (not pins.stby[finger]) and bool(np.all(pins.duty[finger] == 0))


def test_host_silence_applies_hold_and_latches_host_timeout(
    board: EmulatedBoard, hand: Hand
) -> None:
    hand.pose("fist", duration=0.5)
    assert hand.safety() == M.Safety(heartbeat_timeout=0.5, safe_action=M.SafeAction.HOLD)
    last_heard = streamed(hand).board_time
    held = board.theta2.copy()
    silent(hand, 0.8)
    st = streamed(hand)
    for f in st:
        assert F.HOST_TIMEOUT in f.faults and f.mode == M.ControlMode.POSITION
        assert F.HOST_TIMEOUT in new_faults(hand, f.name)
    events = [e for e in hand.faults_seen if e.new_faults & F.HOST_TIMEOUT]
    assert 0.45 < events[0].board_time - last_heard < 0.6  # the 0.5 s timeout
    # HOLD: the fingers stay where they were, under closed-loop control, motors powered
    np.testing.assert_allclose(board.theta2, held, atol=0.03)
    assert board.pins.stby.all()
    # the fault stays latched: nothing is driven again until the host clears it
    with pytest.raises(FingerFaultError, match="HOST_TIMEOUT"):
        hand.move({"index": 0.2}, 0.2)
    hand.clear_faults()
    hand.pose("open", duration=0.5)


def test_host_silence_with_safe_action_coast_turns_the_motors_off(
    board: EmulatedBoard, hand: Hand
) -> None:
    hand.set_safety(heartbeat_timeout=0.3, safe_action="coast")
    hand.pose("fist", duration=0.5)
    assert board.tendon_tension[:, 0].min() > 0.5  # pulling, before
    silent(hand, 0.5)
    st = streamed(hand)
    assert [f.mode for f in st] == [M.ControlMode.COAST] * 5
    assert all(F.HOST_TIMEOUT in f.faults for f in st)
    assert all(motors_off(board, i) for i in range(5))
    assert np.all(board.motor_current == 0.0)


@pytest.mark.parametrize(
    ("inject", "bit"),
    [
        (lambda b: b.unplug_encoder(2), F.ENCODER_RANGE),  # the AS5600's cable is off
        (lambda b: b.shift_encoder(2, -0.5), F.ENCODER_JUMP),  # its magnet slipped
    ],
    ids=["unplugged", "slipped"],
)
def test_encoder_faults_stop_the_finger(board: EmulatedBoard, hand: Hand, inject, bit) -> None:
    hand.pose("fist", duration=0.5)
    inject(board)
    st = streamed(hand)
    assert bit in new_faults(hand, "middle")
    assert bit in st["middle"].faults and st["middle"].mode == M.ControlMode.COAST
    assert motors_off(board, 2)
    for i in (0, 1, 3, 4):  # the others carry on
        assert not st[i].faults and st[i].mode == M.ControlMode.POSITION
        assert board.pins.stby[i]
    with pytest.raises(FingerFaultError, match=f"middle: {bit.name}"):
        hand.move({"middle": 0.3}, 0.3)
    board.plug_encoder(2)
    board.shift_encoder(2, 0.0)
    hand.clock.sleep(0.02)  # until the firmware's readings are all taken after the repair
    hand.clear_faults("middle")
    hand.move({"middle": 0.3}, 0.4)  # driven again once the cause is gone and cleared
    assert board.theta2[2] == pytest.approx(0.3, abs=0.04)


def test_a_blocked_finger_stalls_and_stops(board: EmulatedBoard, hand: Hand) -> None:
    hand.pose("open", duration=0.3)
    board.block_finger(1, 0.3, direction="flexion")  # an obstacle at 0.3 rad
    trace: list[HandState] = []
    hand.on_state(trace.append)
    with pytest.raises(FingerFaultError, match="index: STALL"):
        hand.move({"index": 1.2}, 0.3, timeout=3.0)
    st = streamed(hand)
    assert F.STALL in new_faults(hand, "index") and F.STALL in st["index"].faults
    assert st["index"].mode == M.ControlMode.COAST
    assert board.theta2[1] < 0.3 + 1e-3  # never past the obstacle (it may sag back, unpowered)
    assert max(f["index"].theta2 for f in trace) == pytest.approx(0.3, abs=0.03)  # reached it
    assert motors_off(board, 1) and np.all(board.motor_current[1] == 0.0)
    assert not any(st[i].faults for i in (0, 2, 3, 4))


def test_out_of_range_targets_are_refused_and_nothing_moves(
    board: EmulatedBoard, hand: Hand
) -> None:
    hand.pose("open", duration=0.3)
    hand.clock.sleep(0.3)
    before_target = hand.state().target
    before_plant = board.theta2.copy()
    hi = hand.limits("ring").theta2_max
    wire = M.SetTargets(kind=M.TargetKind.JOINT2_ANGLE, mask=0b01000, value=(0, 0, 0, hi + 0.05, 0))
    with pytest.raises(NackError) as info:  # the firmware's own check, past the host's
        hand.link.request(wire)
    assert info.value.code == M.ErrorCode.OUT_OF_RANGE and info.value.detail == 0x80 | 3
    with pytest.raises(TargetError, match=r"'ring'.*limits"):
        hand.set_targets({"ring": 1.05}, kind="flexion")
    bad_q = M.SetTargets(kind=M.TargetKind.TENDON_Q, mask=0b00001, value=(0.05, 0, 0, 0, 0))
    with pytest.raises(NackError, match="OUT_OF_RANGE"):
        hand.link.request(bad_q)
    hand.clock.sleep(0.3)
    np.testing.assert_array_equal(hand.state().target, before_target)  # no target changed
    np.testing.assert_allclose(board.theta2, before_plant, atol=0.01)  # nothing moved


def test_a_reading_beyond_the_joint_limit_latches(board: EmulatedBoard, hand: Hand) -> None:
    # The little finger's encoder drifts (steps below the jump limit) until it reads beyond
    # the joint's upper limit by more than the margin.
    lim = hand.limits("little")
    step = 0.8 * lim.encoder_jump
    shift = 0.0
    while shift < lim.theta2_max + lim.limit_margin + 0.05:
        shift += step
        board.shift_encoder(4, shift)
        hand.clock.sleep(0.01)
    st = streamed(hand)
    assert F.JOINT_LIMIT in new_faults(hand, "little")
    assert F.ENCODER_JUMP not in st["little"].faults  # a drift, not a jump
    assert F.JOINT_LIMIT in st["little"].faults
    with pytest.raises(FingerFaultError, match="little: JOINT_LIMIT"):
        hand.set_mode("position", "little")


def test_a_hung_loop_stops_the_motors_then_the_watchdog_resets(
    board: EmulatedBoard, hand: Hand
) -> None:
    # The timer interrupt still runs: the firmware's tick sees loop() stop (20 ticks), turns
    # every motor off, and the watchdog (30 ms, fed only by loop()) resets the board.
    hand.pose("fist", duration=0.3)
    assert not all(motors_off(board, f) for f in range(5))
    board.hang_firmware(interrupts=True)
    hung_at = board.sim_time
    assert board.run_until(lambda b: all(motors_off(b, f) for f in range(5)), timeout=0.1)
    assert board.sim_time - hung_at < 0.025  # 20 ticks, before the watchdog
    hand.clock.sleep(0.3)
    with pytest.raises(BoardResetError):
        hand.state()
    assert hand.last_boot is not None
    assert hand.last_boot.reset_cause == M.ResetCause.WATCHDOG
    assert hand.reconnect().reset_cause == M.ResetCause.WATCHDOG
    assert all(motors_off(board, f) for f in range(5))  # a reset board waits for the host


def test_a_hang_with_interrupts_off_is_reset_by_the_watchdog(
    board: EmulatedBoard, hand: Hand
) -> None:
    # Nothing of the firmware runs (the PWM hardware keeps its last duty): only the watchdog
    # gets the board back, within its 30 ms period.
    hand.pose("fist", duration=0.3)
    board.hang_firmware(interrupts=False)
    hung_at = board.sim_time
    assert board.run_until(lambda b: b.reset_cause == "watchdog", timeout=0.3)
    assert board.sim_time - hung_at < 0.034  # WDTO_30MS: 4K cycles of 128 kHz = 0.032 s
    hand.clock.sleep(0.05)
    with pytest.raises(BoardResetError):
        hand.state()
    assert hand.reconnect().reset_cause == M.ResetCause.WATCHDOG
    assert all(motors_off(board, f) for f in range(5))


def test_a_corrupt_saved_configuration_boots_on_defaults_and_says_so(
    board: EmulatedBoard, hand: Hand, tmp_path: Path
) -> None:
    hand.set_safety(heartbeat_timeout=0.8, safe_action="coast")
    hand.save_config()
    board.reset()
    with pytest.raises(BoardResetError):
        hand.state()
    identity = hand.reconnect()
    assert identity.config_status == M.ConfigStatus.LOADED  # the saved one, intact
    assert hand.safety().heartbeat_timeout == pytest.approx(0.8)
    image = bytearray(board.eeprom)
    image[40] ^= 0x04  # one bit of the stored gains flips
    (tmp_path / "eeprom.bin").write_bytes(image)
    board.load_eeprom(tmp_path / "eeprom.bin")
    board.reset()
    hand.clock.sleep(0.05)
    assert hand.last_boot is not None
    assert hand.last_boot.config_status == M.ConfigStatus.DEFAULTS_CORRUPT  # in the stream
    identity = hand.reconnect()
    assert identity.config_status == M.ConfigStatus.DEFAULTS_CORRUPT
    assert identity.reset_cause == M.ResetCause.RESET_PIN
    assert hand.safety() == M.Safety(heartbeat_timeout=0.5, safe_action=M.SafeAction.HOLD)
