"""Protocol dispatch: every request, its reply, and every way to get it wrong.

A refused request is answered with a nack naming the field or finger, and changes nothing:
`snapshot()` is compared before and after.
"""

from __future__ import annotations

import itertools
import math
import struct

import numpy as np
import pytest
from fwsim import Sim, m, raw_body

from utrf.protocol.codec import WIRE_TYPES
from utrf.protocol.framing import encode_frame

REQUESTS = [c for c in m.MESSAGES if c.DIRECTION == "host_to_board"]

VALID: dict[type[m.Message], m.Message] = {
    m.Identify: m.Identify(),
    m.Ping: m.Ping(token=0xDEADBEEF),
    m.Heartbeat: m.Heartbeat(),
    m.Goodbye: m.Goodbye(),
    m.SetTargets: m.SetTargets(
        kind=m.TargetKind.JOINT2_ANGLE, mask=0b11, value=(0.2, -0.1, 0, 0, 0)
    ),
    m.SetMode: m.SetMode(mask=0b1, mode=(1, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5),
    m.SetTelemetry: m.SetTelemetry(rate_hz=0),
    m.Move: m.Move(
        move_id=1,
        kind=m.TargetKind.JOINT2_ANGLE,
        mask=0b1,
        value=(0.2, 0, 0, 0, 0),
        duration=(0.5, 0, 0, 0, 0),
    ),
    m.GetMotion: m.GetMotion(finger=1),
    m.SetMotion: m.SetMotion(finger=1, max_speed=2.0, max_accel=10.0, kv=0.3, ka=0.01),
    m.GetGains: m.GetGains(finger=1),
    m.SetGains: m.SetGains(
        finger=1,
        kp=4.0,
        ki=1.0,
        kd=0.02,
        d_cutoff_hz=40.0,
        deadband_duty=0.02,
        slew_per_s=30.0,
        max_duty=0.9,
        pretension_duty=0.05,
    ),
    m.GetLimits: m.GetLimits(finger=1),
    m.SetLimits: m.SetLimits(
        finger=1,
        theta2_min=-1.0,
        theta2_max=1.5,
        limit_margin=0.1,
        stall_error=0.2,
        stall_motion=0.02,
        stall_time=0.5,
        encoder_jump=0.2,
    ),
    m.GetSafety: m.GetSafety(),
    m.SetSafety: m.SetSafety(heartbeat_timeout=1.0, safe_action=m.SafeAction.COAST),
    m.GetFingerConfig: m.GetFingerConfig(finger=1),
    m.SetFingerConfig: m.SetFingerConfig(
        finger=1,
        actuation=m.Actuation.ANTAGONISTIC,
        encoder_offset=3.0,
        encoder_invert=0,
        motor_invert=0,
    ),
    m.SaveConfig: m.SaveConfig(),
    m.LoadConfig: m.LoadConfig(source=m.ConfigSource.DEFAULTS),
    m.CalibrateZero: m.CalibrateZero(mask=0b100),
    m.ClearFaults: m.ClearFaults(mask=0b11111),
    m.GetState: m.GetState(),
    m.GetStats: m.GetStats(),
    m.GetStatus: m.GetStatus(),
    m.ResetStats: m.ResetStats(),
}


def snapshot(sim: Sim) -> tuple:
    """Everything a request could change: settings, finger states, targets, the EEPROM."""
    cfg = [sim.ok(m.GetSafety())]
    for f in range(5):
        cfg += [
            sim.ok(m.GetGains(finger=f)),
            sim.ok(m.GetLimits(finger=f)),
            sim.ok(m.GetFingerConfig(finger=f)),
            sim.ok(m.GetMotion(finger=f)),
        ]
    fingers = [(x.mode, x.faults, x.target) for x in (sim.finger(f) for f in range(5))]
    eeprom = bytes(sim.eeprom()[: sim.lib.fw_config_image_bytes()])
    return tuple(cfg), tuple(fingers), eeprom, sim.status().config_status


def bad_raw_values(field: m.Field) -> list[int | float]:
    """Raw wire values of `field` that its range (or enum) excludes."""
    _, tlo, thi = WIRE_TYPES[field.type]
    if field.type == "f32":
        out = [math.nan, math.inf]
        if field.max is not None:
            out.append(field.max * 2 + 1)
        if field.min is not None:
            out.append(field.min - 1 if field.min <= 0 else field.min / 2)
        return out
    if field.enum is not None:
        top = max(field.enum._value2member_map_) + 1
        return [top] if top <= thi else []
    out = []
    if field.raw_max is not None and field.raw_max < thi:
        out.append(field.raw_max + 1)
    if field.raw_min is not None and field.raw_min > tlo:
        out.append(field.raw_min - 1)
    return out


def out_of_range_cases():
    for cls in REQUESTS:
        valid = list(VALID[cls].to_raw().values())
        for field in cls.FIELDS:
            for bad in bad_raw_values(field):
                raw = [list(v) if isinstance(v, tuple) else v for v in valid]
                if field.count is None:
                    raw[field.index] = bad
                elif cls.MASKED_BY is not None:
                    # only a finger in the mask is checked: the lowest one
                    mask = VALID[cls].to_raw()[cls.MASKED_BY]
                    raw[field.index][(mask & -mask).bit_length() - 1] = bad
                else:
                    raw[field.index][field.count - 1] = bad
                flat = []
                for v in raw:
                    flat.extend(v if isinstance(v, list) else [v])
                yield pytest.param(
                    cls, field.index, cls._STRUCT.pack(*flat), id=f"{cls.NAME}.{field.name}={bad}"
                )


def test_every_request_has_an_example() -> None:
    assert set(VALID) == set(REQUESTS)


def test_boot_is_the_first_frame(fwlib) -> None:
    sim = Sim(fwlib)
    sim.power_on(settle_ms=0)
    sim.run(1)
    first = sim.frames[0]
    assert first.seq == m.BOARD_SEQ_FLAG and isinstance(first.msg, m.Boot)
    assert (first.msg.protocol_version, first.msg.schema_hash) == (
        m.PROTOCOL_VERSION,
        m.SCHEMA_HASH,
    )


@pytest.mark.parametrize("cls", REQUESTS, ids=lambda c: c.NAME)
def test_every_request_gets_its_reply(sim: Sim, cls: type[m.Message]) -> None:
    if cls is m.CalibrateZero:
        sim.run(2)  # needs a reading first
    if cls is m.Move:  # moves a finger under closed-loop control
        sim.run(2)
        sim.ok(m.SetMode(mask=0b1, mode=(2, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    reply = sim.request(VALID[cls], ms=2 if cls is not m.SaveConfig else 2000)
    expected = cls.REPLY
    assert isinstance(reply.msg, expected), reply.msg
    if expected is m.Ack:
        assert reply.msg.msg_id == cls.ID
    assert reply.seq == sim._seq  # the request's seq comes back


@pytest.mark.parametrize("cls", REQUESTS, ids=lambda c: c.NAME)
def test_wrong_length_is_refused_and_changes_nothing(sim: Sim, cls) -> None:
    before = snapshot(sim)
    body = VALID[cls].encode()
    for bad in (body + b"\x00", body[:-1] if body else None):
        if bad is None:
            continue
        nack = sim.nack(cls.ID, bad)
        assert (nack.msg_id, nack.code) == (cls.ID, m.ErrorCode.BAD_LENGTH)
        assert nack.detail == cls.SIZE
    assert snapshot(sim) == before


@pytest.mark.parametrize("cls,index,body", list(out_of_range_cases()))
def test_out_of_range_field_is_refused_and_changes_nothing(sim: Sim, cls, index, body) -> None:
    before = snapshot(sim)
    nack = sim.nack(cls.ID, body)
    assert (nack.msg_id, nack.code, nack.detail) == (cls.ID, m.ErrorCode.OUT_OF_RANGE, index)
    assert snapshot(sim) == before


@pytest.mark.parametrize("msg_id", [0x00, 0x05, 0x14, 0x3F, 0x81, 0x90, 0xF0, 0xFF])
def test_unknown_ids_are_refused(sim: Sim, msg_id: int) -> None:
    before = snapshot(sim)
    nack = sim.nack(msg_id, b"\x01\x02")
    assert (nack.msg_id, nack.code) == (msg_id, m.ErrorCode.UNKNOWN_ID)
    assert nack.detail == 0  # as spec.toml's ErrorCode says
    assert snapshot(sim) == before


def test_bad_crc_is_refused_with_the_frames_seq(sim: Sim) -> None:
    before = snapshot(sim)
    frame = bytearray(encode_frame(0x42, m.SetMode.ID, VALID[m.SetMode].encode()))
    # A damaged CRC byte (a data byte of the COBS frame, not a code byte, and not 0x00).
    assert frame[-2] not in (0x00, 0x40)
    frame[-2] ^= 0x40
    sim.send_raw(bytes(frame))
    sim.run(2)
    nack = next(r for r in sim.frames if r.seq == 0x42).msg
    assert (nack.msg_id, nack.code, nack.detail) == (m.SetMode.ID, m.ErrorCode.BAD_CRC, 0)
    assert snapshot(sim) == before
    assert sim.ok(m.GetStats()).rx_crc_errors == 1


@pytest.mark.parametrize("seq", [0x42, 0x00, 0x7F])
def test_a_damaged_frame_whose_seq_reads_as_a_board_seq_is_counted_not_answered(
    sim: Sim, seq: int
) -> None:
    """A BAD_CRC nack echoes the damaged frame's seq; one with bit 7 set would read as a board
    frame (protocol/README.md, Sequence numbers): the board counts the frame and says nothing."""
    frame = bytearray(encode_frame(seq, m.SetMode.ID, VALID[m.SetMode].encode()))
    damaged = bytearray(frame)
    if seq == 0:  # seq 0 is a COBS code's zero: damage the msg_id's place instead, then flip
        damaged = bytearray(encode_frame(0x80, m.SetMode.ID, VALID[m.SetMode].encode()))
        damaged[-2] ^= 0x01  # a CRC byte: the frame is damaged, its seq reads 0x80
    else:
        assert damaged[1] == seq
        damaged[1] ^= 0x80  # the seq byte, bit 7 flipped on the line
    sim.take()
    sim.send_raw(bytes(damaged))
    sim.run(3)
    assert [r for r in sim.frames if r.msg_id == m.Nack.ID] == []
    assert sim.ok(m.GetStats()).rx_crc_errors == 1
    # the link goes on: the undamaged frame is answered
    sim.send_raw(bytes(frame))
    sim.run(2)
    assert any(r.seq == seq and r.msg_id == m.Ack.ID for r in sim.frames)


def test_framing_errors_are_counted_not_answered(sim: Sim) -> None:
    before = snapshot(sim)
    sim.take()
    sim.send_raw(b"\x09\x01\x00")  # COBS says 8 more bytes, the frame ends after 1
    sim.send_raw(b"\x02\x00")  # too short for seq, id and a CRC
    sim.send_raw(b"\x01" * 200 + b"\x00")  # longer than any frame
    sim.run(3)
    assert sim.frames == []
    stats = sim.ok(m.GetStats())
    assert stats.rx_framing_errors == 3
    assert snapshot(sim) == before
    # The receiver is in step again: the next frame is answered.
    assert isinstance(sim.ok(m.Ping(token=7)), m.Pong)


def test_ping_echoes_its_token_with_the_board_time(sim: Sim) -> None:
    first = sim.ok(m.Ping(token=123456789))
    sim.run(250)
    second = sim.ok(m.Ping(token=42))
    assert (first.token, second.token) == (123456789, 42)
    assert second.board_time - first.board_time == pytest.approx(0.252, abs=0.002)


def test_identity(sim: Sim) -> None:
    ident = sim.ok(m.Identify())
    assert (ident.protocol_version, ident.schema_hash) == (m.PROTOCOL_VERSION, m.SCHEMA_HASH)
    assert ident.finger_count == 5
    assert ident.loop_rate_hz == 1000
    assert ident.max_telemetry_hz == m.MAX_TELEMETRY_HZ == 1000


def test_set_targets_in_every_unit(sim: Sim) -> None:
    from utrf.models import kinematics
    from utrf.models.geometry import HandGeometry

    geom = HandGeometry.default().fingers[1].geometry
    sim.ok(m.SetTargets(kind=m.TargetKind.TENDON_Q, mask=0b10, value=(0, 0.004, 0, 0, 0)))
    assert sim.finger(1).target_rad == pytest.approx(0.004 / geom.guide_radii_m[1], abs=5e-4)
    sim.ok(m.SetTargets(kind=m.TargetKind.FLEXION, mask=0b10, value=(0, 0.5, 0, 0, 0)))
    q = float(kinematics.q_from_flexion(geom, 0.5))
    assert sim.finger(1).target_rad == pytest.approx(q / geom.guide_radii_m[1], abs=5e-4)
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=0b10, value=(0, -0.7, 0, 0, 0)))
    assert sim.finger(1).target_rad == pytest.approx(-0.7, abs=2e-4)
    before = snapshot(sim)
    for kind, value in (
        (m.TargetKind.FLEXION, 1.2),
        (m.TargetKind.FLEXION, -0.1),
        (m.TargetKind.TENDON_Q, 0.03),
        (m.TargetKind.JOINT2_ANGLE, 2.5),
    ):
        body = raw_body(m.SetTargets, int(kind), 0b10, 0, round(value * 1e6), 0, 0, 0)
        nack = sim.nack(m.SetTargets.ID, body)
        assert (nack.code, nack.detail) == (m.ErrorCode.OUT_OF_RANGE, 0x80 | 1)
    assert snapshot(sim) == before


def test_cross_field_checks(sim: Sim) -> None:
    before = snapshot(sim)
    gains = m.SetGains(
        finger=0,
        kp=3.0,
        ki=2.0,
        kd=0.05,
        d_cutoff_hz=30.0,
        deadband_duty=0.0,
        slew_per_s=20.0,
        max_duty=0.3,
        pretension_duty=0.3,
    )
    nack = sim.nack(m.SetGains.ID, gains.encode())
    assert (nack.code, nack.detail) == (m.ErrorCode.OUT_OF_RANGE, 8)  # pretension >= max_duty
    for lo, hi, field in ((-2.5, 1.0, 1), (-1.0, 2.5, 2), (1.0, 0.5, 2)):  # geometry: +-1.65
        limits = m.SetLimits(
            finger=0,
            theta2_min=lo,
            theta2_max=hi,
            limit_margin=0.1,
            stall_error=0.2,
            stall_motion=0.02,
            stall_time=0.5,
            encoder_jump=0.2,
        )
        nack = sim.nack(m.SetLimits.ID, limits.encode())
        assert (nack.code, nack.detail) == (m.ErrorCode.OUT_OF_RANGE, field)
    assert snapshot(sim) == before


def test_hardware_changes_need_an_idle_finger(sim: Sim) -> None:
    sim.ok(m.SetMode(mask=0b10, mode=(0, 2, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    before = snapshot(sim)
    cfg = m.SetFingerConfig(
        finger=1, actuation=m.Actuation.ROTARY, encoder_offset=0.0, encoder_invert=0, motor_invert=0
    )
    nack = sim.nack(m.SetFingerConfig.ID, cfg.encode())
    assert (nack.code, nack.detail) == (m.ErrorCode.BUSY, 1)
    nack = sim.nack(m.CalibrateZero.ID, m.CalibrateZero(mask=0b10).encode())
    assert (nack.code, nack.detail) == (m.ErrorCode.BUSY, 1)
    assert snapshot(sim) == before


def test_calibrate_zero_takes_the_present_reading(sim: Sim) -> None:
    sim.set_adc(2, 300)  # far from the default zero (mid-band)
    sim.run(2)
    sim.ok(m.ClearFaults(mask=0b100))  # that step was a jump
    sim.run(2)
    assert abs(sim.finger(2).theta_rad) > 1.0
    sim.ok(m.CalibrateZero(mask=0b100))
    sim.run(2)
    assert abs(sim.finger(2).theta_rad) < 1e-3
    offset = sim.ok(m.GetFingerConfig(finger=2)).encoder_offset
    assert offset == pytest.approx(((300 / 1024 - 0.1) / 0.8) * 2 * math.pi, abs=1e-3)
    # A finger whose encoder is out of its band cannot be zeroed.
    sim.set_adc(3, 20)
    sim.run(2)
    nack = sim.nack(m.CalibrateZero.ID, m.CalibrateZero(mask=0b1000).encode())
    assert (nack.code, nack.detail) == (m.ErrorCode.FAULTED, 3)


@pytest.mark.parametrize("rate", [1000, 500, 200, 50])
def test_telemetry_stream_rate_and_seq(sim: Sim, rate: int) -> None:
    sim.ok(m.SetTelemetry(rate_hz=rate))
    sim.take()
    sim.run(1000)
    states = sim.take(m.State)
    assert abs(len(states) - rate) <= 1
    seqs = [s.seq for s in states]
    assert all(s & m.BOARD_SEQ_FLAG for s in seqs)
    assert all(b == (m.BOARD_SEQ_FLAG | ((a + 1) & 0x7F)) for a, b in itertools.pairwise(seqs))
    times = [s.msg.board_time for s in states]
    assert times[-1] - times[0] == pytest.approx((len(states) - 1) / rate, abs=0.0015)
    sim.ok(m.SetTelemetry(rate_hz=0))
    sim.take()
    sim.run(100)
    assert sim.take(m.State) == []


def test_a_full_transmit_buffer_drops_stream_frames_and_counts_them(sim: Sim) -> None:
    sim.ok(m.SetTelemetry(rate_hz=500))
    sim.run(20)
    last_before = sim.take(m.State)[-1]
    sim.lib.fw_set_tx_room(40)  # less than a state frame: nothing fits for 100 ms
    sim.run(100)
    sim.lib.fw_set_tx_room(0xFFFF)
    sim.run(10)
    after = sim.take(m.State)
    dropped = sim.ok(m.GetStats()).tx_dropped
    slots = sim.lib.fw_stream_slots()
    assert slots >= 2
    # 50 samples fell due; the first slots waited in the board's ring and went out
    # late, with their own board time; the rest were dropped.
    assert 49 - slots <= dropped <= 51 - slots
    frames = [last_before, *after]
    steps = [((b.seq & 0x7F) - (a.seq & 0x7F)) % 128 for a, b in itertools.pairwise(frames)]
    # The seq counted the dropped frames too: the host sees one gap of exactly that size,
    # after the samples that waited.
    assert steps[:slots] == [1] * slots
    assert steps[slots] == dropped + 1
    assert set(steps[slots + 1 :]) == {1}
    late = [f.msg.board_time - last_before.msg.board_time for f in after[:slots]]
    assert late == pytest.approx([0.002 * (k + 1) for k in range(slots)], abs=1e-9)


def test_state_reports_angles_targets_and_the_host_derives_the_tip(sim: Sim) -> None:
    from utrf.hand.state import TipModel
    from utrf.models import kinematics
    from utrf.models.geometry import HandGeometry

    hand = HandGeometry.default()
    geom = hand.fingers[4].geometry
    for k in range(1, 7):
        sim.set_angle(4, 0.1 * k)
        sim.run(1)
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=0b10000, value=(0, 0, 0, 0, 0.9)))
    st = sim.ok(m.GetState())
    assert st.theta2[4] == pytest.approx(0.6, abs=0.01)  # the ADC's resolution
    tip = kinematics.tip_position(geom, kinematics.q_from_theta2(geom, st.theta2[4]))
    x, y = TipModel(hand).tip(4, st.theta2[4])
    assert (x, y) == pytest.approx((tip[0], tip[1]), abs=1e-5)


@pytest.mark.parametrize("sent", [0.9, 0.3, -0.2, 1.0001, 0.12345])
def test_state_target_reads_back_what_was_sent_at_the_boards_resolution(
    sim: Sim, sent: float
) -> None:
    # The board keeps a target in counts of 2 pi / 32768 rad and the state carries those
    # counts: what comes back is the value sent, rounded once to that resolution.
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=0b1000, value=(0, 0, 0, sent, 0)))
    res = m.State.FIELDS[3].scale
    assert sim.ok(m.GetState()).target[3] == round(sent / res) * res


def test_a_new_fault_is_reported_once(sim: Sim) -> None:
    sim.set_adc(0, 5)
    sim.run(20)
    faults = sim.take(m.Fault)
    assert len(faults) == 1
    assert faults[0].seq & m.BOARD_SEQ_FLAG
    msg = faults[0].msg
    assert (msg.finger, msg.new_faults) == (0, m.FaultBits.ENCODER_RANGE)
    assert msg.faults[0] == m.FaultBits.ENCODER_RANGE


def test_stats_count_and_reset(sim: Sim) -> None:
    sim.lib.fw_set_tick_cycles(4800)  # what the host layer says each tick took
    sim.ok(m.ResetStats())
    for _ in range(3):
        sim.ok(m.Heartbeat())
    sim.nack(0x77, b"")
    sim.lib.fw_add_rx_lost(5)
    sim.lib.fw_add_uart_errors(2, 3)
    sim.run(1100)
    stats = sim.ok(m.GetStats())
    assert stats.rx_frames == 5  # 3 heartbeats, the bad id, this request
    assert stats.nacks == 1
    assert stats.rx_overruns == 5
    assert (stats.uart_overruns, stats.uart_frame_errors) == (2, 3)
    assert stats.ticks >= 1100
    assert stats.tick_worst == pytest.approx(300e-6)
    assert stats.tick_mean == pytest.approx(300e-6)
    sim.ok(m.ResetStats())
    stats = sim.ok(m.GetStats())
    assert (stats.rx_frames, stats.nacks, stats.rx_overruns) == (1, 0, 0)
    assert (stats.uart_overruns, stats.uart_frame_errors) == (0, 0)


def test_repeated_set_mode_is_harmless(sim: Sim) -> None:
    """set_mode is idempotent: a resent frame does not restart the PID."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1, value=(0.02, 0, 0, 0, 0)))
    mode = m.SetMode(mask=1, mode=(2, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5)
    sim.ok(mode)
    sim.run(300)  # a small error, far from saturation: the integrator grows
    i_before = sim.finger(0).integrator31
    assert i_before > 0
    seq = sim.send(mode)
    sim.loop()  # the resent frame, and no tick: a restart would show at once
    assert [r for r in sim.frames if r.seq == seq]
    assert sim.finger(0).integrator31 == i_before


def test_a_request_with_the_board_seq_flag_is_ignored_and_counted(sim: Sim) -> None:
    # Its reply would carry a board seq, which the host reads as a board-initiated frame.
    sim.take()
    sim.send_raw(encode_frame(0x85, m.Ping.ID, struct.pack("<I", 9)))
    sim.send_raw(encode_frame(0xC0, m.SetMode.ID, VALID[m.SetMode].encode()))
    sim.run(2)
    assert [r for r in sim.frames if r.seq in (0x85, 0xC0) or isinstance(r.msg, m.Pong)] == []
    assert sim.finger(0).mode == m.ControlMode.COAST  # the set_mode was not applied
    assert sim.ok(m.GetStats()).rx_ignored == 2


# --- ranges only where the mask reads ---------------------------------------------------------


def test_set_mode_checks_ranges_only_on_the_fingers_in_its_mask(sim: Sim) -> None:
    # Finger 4 is not in the mask: its duty (out of range) and mode (no ControlMode) are not
    # read, so they cannot refuse the request.
    body = raw_body(m.SetMode, 0b1, 2, 0, 0, 0, 99, 0, 0, 0, 0, 5000, 0, 0, 0, 0, 4000)
    sim.run(5)
    assert isinstance(sim.request_body(m.SetMode.ID, body).msg, m.Ack)
    assert sim.finger(0).mode == m.ControlMode.POSITION
    assert sim.finger(4).mode == m.ControlMode.COAST
    # In the mask, the same value is refused, naming the field.
    body = raw_body(m.SetMode, 0b10001, 2, 0, 0, 0, 2, 0, 0, 0, 0, 5000, 0, 0, 0, 0, 0)
    nack = sim.nack(m.SetMode.ID, body)
    assert (nack.code, nack.detail) == (m.ErrorCode.OUT_OF_RANGE, 2)


# --- safe resend ------------------------------------------------------------------------------


def test_a_resent_request_is_answered_from_the_cache_not_done_twice(sim: Sim) -> None:
    sim.run(5)
    frame = encode_frame(0x11, m.SetMode.ID, VALID[m.SetMode].encode())
    sim.send_raw(frame)
    sim.run(2)
    first = [r for r in sim.take() if r.seq == 0x11]
    # The ack was lost on the way; meanwhile the finger changed mode by another request.
    sim.ok(m.SetMode(mask=0b1, mode=(0, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    assert sim.finger(0).mode == m.ControlMode.COAST
    sim.take()
    sim.send_raw(frame)  # the resend of seq 0x11: the same bytes
    sim.run(2)
    again = [r for r in sim.take() if r.seq == 0x11]
    assert len(first) == 1  # that ack was answered once, ...
    # ... and the resend after another request is a new request (the cache held one reply)
    assert [r.body for r in again] == [first[0].body]
    assert sim.finger(0).mode == m.ControlMode.BRAKE


BU_PER_RAD = 32768 / (2 * math.pi)  # the board's angle counts


def test_a_resend_right_after_the_request_gets_the_same_reply_and_changes_nothing(
    sim: Sim,
) -> None:
    # calibrate_zero is the request that would do harm twice: the encoder moved in between.
    sim.set_angle(2, 0.2)
    sim.run(5)
    before = sim.ok(m.GetStats()).rx_repeats
    frame = encode_frame(0x21, m.CalibrateZero.ID, m.CalibrateZero(mask=0b100).encode())
    sim.send_raw(frame)
    sim.run(2)
    for k in range(1, 4):  # the finger moves on (slowly: no encoder jump)
        sim.set_angle(2, 0.2 + 0.1 * k)
        sim.run(2)
    sim.send_raw(frame)  # its ack was lost: the host sends the same frame again
    sim.run(2)
    acks = [r for r in sim.take() if r.seq == 0x21]
    assert len(acks) == 2 and acks[0].body == acks[1].body  # the cached reply, as it was
    assert sim.ok(m.GetStats()).rx_repeats == before + 1
    # Zero was taken once, at 0.2 rad: the finger now reads 0.3 rad, not 0.
    assert sim.ok(m.GetState()).theta2[2] == pytest.approx(0.3, abs=0.01)


def test_a_resent_save_config_under_way_is_not_refused_busy(sim: Sim) -> None:
    frame = encode_frame(0x33, m.SaveConfig.ID, b"")
    sim.send_raw(frame)
    sim.run(5)
    sim.send_raw(frame)  # the host's resend while the EEPROM is being written
    sim.run(3000)
    replies = [r for r in sim.take() if r.seq == 0x33]
    assert [type(r.msg) for r in replies] == [m.Ack]


def test_same_seq_different_bytes_is_a_new_request(sim: Sim) -> None:
    sim.run(5)
    a = m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b1, (0.3, 0, 0, 0, 0))
    b = m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b1, (0.4, 0, 0, 0, 0))
    sim.send_raw(encode_frame(0x44, a.ID, a.encode()))
    sim.run(2)
    sim.send_raw(encode_frame(0x44, b.ID, b.encode()))
    sim.run(2)
    assert sim.finger(0).target == round(0.4 * BU_PER_RAD)


@pytest.mark.parametrize("hb_seq,resend_applied", [(0x52, False), (0x10, True)])
def test_heartbeats_keep_the_reply_cache_until_half_a_round_of_seqs(
    sim: Sim, hb_seq: int, resend_applied: bool
) -> None:
    # Heartbeats go out while a request waits: a resend after them is still a resend. 64 seqs
    # on, the cached seq could come round for a new request with the same bytes: forgotten.
    sim.set_angle(2, 0.2)
    sim.run(5)
    zero = encode_frame(0x50, m.CalibrateZero.ID, m.CalibrateZero(mask=0b100).encode())
    sim.send_raw(zero)
    sim.run(2)
    for k in range(1, 4):  # the finger moves on (slowly: no encoder jump)
        sim.set_angle(2, 0.2 + 0.1 * k)
        sim.run(2)
    sim.send_raw(encode_frame(hb_seq, m.Heartbeat.ID, b""))
    sim.run(2)
    sim.send_raw(zero)
    sim.run(2)
    sim.take()
    theta = sim.ok(m.GetState()).theta2[2]
    assert theta == pytest.approx(0.0 if resend_applied else 0.3, abs=0.01)


# --- status and the stream's seq ----------------------------------------------------------------


def test_a_mode_change_sends_a_status_and_the_state_names_it(sim: Sim) -> None:
    sim.ok(m.SetTelemetry(rate_hz=1000))
    sim.run(5)
    st0 = sim.take(m.State)[-1].msg
    status0 = sim.ok(m.GetStatus())
    assert st0.status_seq == status0.change
    sim.ok(m.SetMode(mask=0b110, mode=(0, 1, 1, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    sim.run(5)
    (status,) = [r for r in sim.take(m.Status)]
    assert status.seq & m.BOARD_SEQ_FLAG
    assert status.msg.change == (status0.change + 1) % 256
    assert status.msg.mode[1:3] == (m.ControlMode.BRAKE, m.ControlMode.BRAKE)
    assert sim.take(m.State)[-1].msg.status_seq == status.msg.change
    sim.ok(m.SetMode(mask=0b110, mode=(0, 1, 1, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    sim.run(5)
    assert sim.take(m.Status) == []  # nothing changed: no status


def test_fault_and_status_frames_share_the_streams_seq_with_no_gap(sim: Sim) -> None:
    from utrf.protocol.engine import Engine

    sim.ok(m.SetTelemetry(rate_hz=1000))
    sim.run(10)
    sim.take()
    sim.set_adc(0, 5)  # encoder unplugged: ENCODER_RANGE latches, a fault and a status go out
    sim.run(50)
    frames = [r for r in sim.take() if r.seq & m.BOARD_SEQ_FLAG]
    kinds = {type(r.msg) for r in frames}
    assert {m.State, m.Fault, m.Status} <= kinds
    seqs = [r.seq for r in frames]
    assert all(b == (m.BOARD_SEQ_FLAG | ((a + 1) & 0x7F)) for a, b in itertools.pairwise(seqs))
    # The host's loss rule counts over every board-initiated frame: nothing lost.
    engine = Engine()
    for r in frames:
        engine.receive(encode_frame(r.seq, r.msg_id, r.body), 0.0)
    assert engine.stats().stream_lost == 0
    assert engine.stats().stream_frames == len(frames)


def test_a_1khz_stream_is_whole_with_five_fingers_moving(sim: Sim) -> None:
    sim.run(5)
    sim.ok(m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b11111, (0.0,) * 5))
    sim.ok(m.SetMode(mask=0b11111, mode=(2,) * 5, duty=(0,) * 5, effort=(0,) * 5))
    sim.ok(m.SetTelemetry(rate_hz=1000))
    sim.take()
    for k in range(200):
        sim.set_angles([0.2 * math.sin(0.05 * k + f) for f in range(5)])
        sim.run(5)
        if k % 10 == 0:
            sim.ok(m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b11111, (0.1 * (k % 3),) * 5))
    states = [r for r in sim.frames if isinstance(r.msg, m.State) and r.seq & 0x80]
    assert len(states) >= 990
    ticks = [round(r.msg.board_time * 1000) for r in states]
    assert all((b - a) % 65536 == 1 for a, b in itertools.pairwise(ticks))
    assert sim.ok(m.GetStats()).tx_dropped == 0


# --- entering closed loop: the stored target -----------------------------------------------------


@pytest.mark.parametrize("idle", [m.ControlMode.COAST, m.ControlMode.BRAKE])
@pytest.mark.parametrize("target_sent_while_idle", [True, False])
def test_entering_position_treats_the_target_alike_from_coast_and_brake(
    sim: Sim, idle: m.ControlMode, target_sent_while_idle: bool
) -> None:
    # protocol/README.md: a target sent since the finger left closed loop is the one
    # POSITION goes to; with none, POSITION holds the measured angle. COAST and BRAKE alike.
    def mode(x: m.ControlMode) -> None:
        sim.ok(m.SetMode(mask=0b1, mode=(x, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))

    sim.set_angle(0, 0.2)
    sim.run(5)
    sim.ok(m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b1, (0.6, 0, 0, 0, 0)))
    mode(m.ControlMode.POSITION)
    sim.run(5)
    mode(idle)
    if target_sent_while_idle:
        sim.ok(m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b1, (0.4, 0, 0, 0, 0)))
    mode(m.ControlMode.POSITION)
    want = 0.4 if target_sent_while_idle else 0.2
    assert sim.ok(m.GetState()).target[0] == pytest.approx(want, abs=0.01)


def test_the_default_heartbeat_timeout_is_the_specs_and_on_the_protocol_page(sim: Sim) -> None:
    from pathlib import Path

    assert sim.ok(m.GetSafety()).heartbeat_timeout == m.DEFAULT_HEARTBEAT_TIMEOUT_S == 0.5
    readme = Path(__file__).resolve().parents[2] / "protocol" / "README.md"
    assert "| default heartbeat timeout | 0.5 s |" in readme.read_text(encoding="utf-8")


def test_the_set_targets_window_is_exactly_the_values_the_count_check_accepts(sim: Sim) -> None:
    # set_targets checks JOINT2_ANGLE values against a window in micro-radians worked out with
    # the limits (dispatch.cpp target_window, by bisection), so that it can ack before it
    # converts them: the window must hold exactly the values whose count (x * M / 2^32,
    # rounded) lies within a count of the limits, and none beyond +-4e6.
    import ctypes

    big_m = 22399067  # round(2^32 * 32768 / (2 pi 1e6)), as bu_from_urad
    k = 4_000_000

    def bu(x: int) -> int:
        return (x * big_m + 2**31) >> 32

    def first_at_least(t: int) -> int:  # smallest x with bu(x) >= t
        return -((-(t * 2**32 - 2**31)) // big_m)

    lo, hi = ctypes.c_int32(), ctypes.c_int32()
    limits = [(-16384, 16384), (-32768, 32767), (-100, 100), (0, 0), (12000, 12345), (-5, -3)]
    limits += [(a, a + d) for a, d in ((-20000, 7), (31000, 1767), (-32768, 0), (777, 4096))]
    for t_min, t_max in limits:
        sim.lib.fw_target_window(t_min, t_max, ctypes.byref(lo), ctypes.byref(hi))
        want_lo = max(-k, first_at_least(t_min - 1))
        want_hi = min(k, first_at_least(t_max + 2) - 1)
        if want_lo > want_hi:  # beyond +-4e6: nothing accepted
            assert lo.value > hi.value, (t_min, t_max)
            continue
        assert (lo.value, hi.value) == (want_lo, want_hi), (t_min, t_max)
        assert bu(want_lo) >= t_min - 1 and (want_lo == -k or bu(want_lo - 1) < t_min - 1)
        assert bu(want_hi) <= t_max + 1 and (want_hi == k or bu(want_hi + 1) > t_max + 1)


def test_the_set_targets_window_and_the_general_range_rule_accept_alike(sim: Sim) -> None:
    """The target range rule has one home (finger::Params::accepts(), which move and the
    other kinds take); set_targets' micro-radian window is its fast path for JOINT2_ANGLE.
    Fed the same values (each window's edges and either side of them, random ones, the ends
    of the range), the two agree."""
    import ctypes

    rng = np.random.default_rng(23)
    lo, hi = ctypes.c_int32(), ctypes.c_int32()
    limits = [(-16384, 16384), (-100, 100), (0, 0), (12000, 12345), (-32768, 32767)]
    limits += [tuple(sorted(rng.integers(-20000, 20000, size=2))) for _ in range(20)]
    for t_min, t_max in limits:
        sim.lib.fw_target_window(int(t_min), int(t_max), ctypes.byref(lo), ctypes.byref(hi))
        values = [lo.value + d for d in (-2, -1, 0, 1)] + [hi.value + d for d in (-1, 0, 1, 2)]
        values += [int(v) for v in rng.integers(-4_100_000, 4_100_000, size=200)]
        values += [-4_000_001, -4_000_000, 4_000_000, 4_000_001, 0]
        for v in values:
            fast = lo.value <= v <= hi.value
            assert bool(sim.lib.fw_target_accepts(int(t_min), int(t_max), v)) == fast, (t_min, v)


def test_joint2_angle_targets_are_the_exact_nearest_count(sim: Sim) -> None:
    # The board turns micro-radians into counts in 32-bit pieces (dispatch.cpp bu_from_urad):
    # every value must come out as the 64-bit form x * M / 2^32 rounded, the sign's both sides
    # and the 16-bit boundaries of x included.
    big_m = 22399067  # round(2^32 * 32768 / (2 pi 1e6))
    values = [0, 1, -1, 65535, 65536, -65536, -65537, 95874, -95874, 700000, -700000]
    values += [(k * 104729) % 1_500_001 - 700_000 for k in range(60)]
    for urad in values:
        body = raw_body(m.SetTargets, int(m.TargetKind.JOINT2_ANGLE), 0b1, urad, 0, 0, 0, 0)
        r = sim.request_body(m.SetTargets.ID, body)
        assert not isinstance(r.msg, m.Nack), (urad, r.msg)
        assert sim.finger(0).target == (urad * big_m + 2**31) >> 32, urad
