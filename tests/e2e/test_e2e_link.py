"""The link under load and under damage, over the emulated UART's real byte timing: the
telemetry rate the firmware sustains and the accounting of every frame lost; line noise that
the protocol rides out without ever applying a wrong setpoint (checked in the firmware's own
reported targets and in the plant, not only in the replies); a reset noticed and recovered
from explicitly; and a host of another protocol refused."""

from __future__ import annotations

import numpy as np
import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import DEFAULT_TOLERANCE, Hand, HandState
from utrf.protocol import messages as M
from utrf.protocol.errors import BoardResetError, SchemaMismatchError

FIST = [1.15, 1.40, 1.40, 1.40, 1.40]


def test_the_handshake_with_the_real_firmware(hand: Hand) -> None:
    ident = hand.identity
    assert (ident.protocol_version, ident.schema_hash) == (M.PROTOCOL_VERSION, M.SCHEMA_HASH)
    assert (ident.finger_count, ident.loop_rate_hz) == (5, 1000)
    assert ident.max_telemetry_hz == M.MAX_TELEMETRY_HZ
    expected = tuple(M.Actuation[f.actuation.upper()] for f in hand.geometry.fingers)
    assert ident.actuation == expected
    assert ident.reset_cause == M.ResetCause.POWER_ON
    assert ident.config_status == M.ConfigStatus.DEFAULTS_BLANK  # a fresh EEPROM
    # the boot came first and was waited for: the handshake went to a running firmware
    assert hand.last_boot is not None and hand.last_boot.reset_cause == M.ResetCause.POWER_ON
    assert hand.link_stats().retries == 0


def test_the_firmware_sustains_its_top_telemetry_rate_while_moving(
    board: EmulatedBoard, hand: Hand
) -> None:
    hand.set_telemetry(M.MAX_TELEMETRY_HZ)
    trace: list[HandState] = []
    hand.on_state(trace.append)
    hand.reset_stats()
    s0 = hand.link_stats()
    t0 = board.sim_time
    # the board runs the paths; the host's heartbeats and polls share the line meanwhile
    hand.clock.sleep(hand.move(FIST, 1.0, wait=False).longest)
    hand.clock.sleep(hand.move([0.3] * 5, 0.5, wait=False).longest)
    elapsed = board.sim_time - t0
    s1 = hand.link_stats()
    received = s1.stream_frames - s0.stream_frames
    lost = s1.stream_lost - s0.stream_lost
    # Every frame due arrived or is counted lost, and both ends count the same losses.
    assert received + lost == pytest.approx(M.MAX_TELEMETRY_HZ * elapsed, abs=2)
    assert lost == hand.stats().tx_dropped
    assert received >= 0.995 * M.MAX_TELEMETRY_HZ * elapsed  # the rate is sustained
    times = np.array([s.board_time for s in trace])
    assert np.mean(np.diff(times)) == pytest.approx(1.0 / M.MAX_TELEMETRY_HZ, rel=0.01)
    # a state frame's bytes each: the line carried them at its own pace, no frame damaged
    assert board.stats["tx_uart_bytes"] >= received * (M.State.SIZE + 6)
    assert s1.crc_errors + s1.framing_errors == s0.crc_errors + s0.framing_errors


def test_frames_lost_on_the_line_are_all_counted(board: EmulatedBoard, hand: Hand) -> None:
    hand.set_telemetry(250)
    hand.clock.sleep(0.05)
    board.set_line_faults("to_host", drop=0.002)  # about one state frame in seven
    s0 = hand.link_stats()
    t0 = board.sim_time
    hand.clock.sleep(1.0)
    board.set_line_faults("both")
    hand.clock.sleep(0.02)
    sent = round(250 * (board.sim_time - t0))
    s1 = hand.link_stats()
    got = s1.stream_frames - s0.stream_frames
    lost = s1.stream_lost - s0.stream_lost
    assert lost > 10  # the damage was real
    assert got + lost == pytest.approx(sent, abs=3)  # every frame received or counted lost
    assert hand.stats().tx_dropped == 0  # the firmware sent them all


def test_line_noise_never_applies_a_wrong_setpoint(board: EmulatedBoard, hand: Hand) -> None:
    hand.set_telemetry(200)
    hand.pose("open", duration=0.3)
    # Every target the host sends, and the plant after every stretch of simulated time.
    sent: list[np.ndarray] = [hand.state().target]
    request = hand.link.request

    def recording(msg, **kw):
        if isinstance(msg, M.SetTargets | M.Move):  # a step, or a path's end
            assert msg.kind == M.TargetKind.JOINT2_ANGLE and msg.mask == 0b11111
            sent.append(np.array(msg.value))
        return request(msg, **kw)

    plant: list[np.ndarray] = []
    run_for, run_until = board.run_for, board.run_until

    def run_for_rec(seconds):
        run_for(seconds)
        plant.append(board.theta2)

    def run_until_rec(predicate, timeout):
        out = run_until(predicate, timeout)
        plant.append(board.theta2)
        return out

    hand.link.request = recording  # type: ignore[method-assign]
    board.run_for = run_for_rec  # type: ignore[method-assign]
    board.run_until = run_until_rec  # type: ignore[method-assign]
    trace: list[HandState] = []
    hand.on_state(trace.append)
    board.set_line_faults("both", corrupt=0.001, drop=0.0005, insert=0.0005)
    board.inject_noise(120, "to_board")
    board.inject_noise(120, "to_host")
    # A move is one frame now: the noise is injected along the way too, while the host
    # polls and sends heartbeats during the paths.
    for targets, duration in ((FIST, 1.0), ([0.2] * 5, 0.8)):
        left = hand.move(targets, duration, wait=False).longest
        while left > 0:
            board.inject_noise(120, "to_board")
            hand.state()
            hand.clock.sleep(min(left, 0.25))
            left -= 0.25
    board.set_line_faults("both")
    hand.move([0.6] * 5, 0.5)  # a clean line again: settles as ever
    # the noise was real, and ridden out by resends
    link, fw = hand.link_stats(), hand.stats()
    assert link.crc_errors + link.framing_errors > 5 and link.retries > 0
    assert fw.rx_crc_errors + fw.rx_framing_errors > 5
    # every setpoint the firmware reports using lies on the way between targets the host
    # sent (the board's paths run between them; to the quantisation)
    legit = np.array(sent)
    lo, hi = legit.min(axis=0), legit.max(axis=0)
    for st in trace:
        assert np.all(st.target > lo - 3e-4) and np.all(st.target < hi + 3e-4), st.target
    # the plant never left the span of the legitimate setpoints
    for theta in plant:
        assert np.all(theta > lo - 0.06) and np.all(theta < hi + 0.06)
    np.testing.assert_allclose(board.theta2, 0.6, atol=DEFAULT_TOLERANCE + 0.01)


def test_a_reset_mid_move_raises_and_reconnect_recovers(board: EmulatedBoard, hand: Hand) -> None:
    hand.pose("fist", duration=0.5)
    t_reset = board.sim_time + 0.3

    def reset_once(st: HandState) -> None:
        if board.sim_time >= t_reset and board.stats["resets"] == 0:
            board.reset()

    hand.on_state(reset_once)
    with pytest.raises(BoardResetError, match="RESET_PIN"):
        hand.pose("open", duration=1.0)
    assert board.sim_time - t_reset < 0.05  # noticed at once, not at the end of the move
    with pytest.raises(BoardResetError):  # every call, until reconnect
        hand.set_targets([0.0] * 5)
    identity = hand.reconnect()
    assert identity.reset_cause == M.ResetCause.RESET_PIN
    st = hand.state()
    assert [f.mode for f in st] == [M.ControlMode.COAST] * 5  # nothing moves on its own
    seq0 = hand.link_stats().stream_frames
    hand.clock.sleep(0.1)
    assert hand.link_stats().stream_frames - seq0 == pytest.approx(10, abs=1)  # telemetry back
    hand.pose("shaka", duration=0.5)


def test_a_host_of_another_protocol_is_refused(
    board: EmulatedBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(M, "SCHEMA_HASH", 0x0BADF00D)  # this host "built from another spec"
    with pytest.raises(SchemaMismatchError) as info:
        Hand.emulated(board)
    board_hash = info.value.board_hash
    assert board_hash != 0x0BADF00D
    version = M.PROTOCOL_VERSION
    assert f"board speaks version {version} (schema 0x{board_hash:08X})" in str(info.value)
    assert f"host speaks version {version} (schema 0x0BADF00D)" in str(info.value)


@pytest.mark.timeout(30)
def test_simulated_sleeps_of_any_length_end_on_time(board: EmulatedBoard, hand: Hand) -> None:
    # A sleep shorter than a clock cycle once spun forever: the board moves in whole exchanges.
    half = board.exchange_period / 2
    for seconds in (0.0, 1e-9, 3e-8, 2e-4, 1.23456789e-3, 0.0101, 0.1003):
        t0 = board.sim_time
        hand.clock.sleep(seconds)
        assert abs(board.sim_time - t0 - seconds) <= half + 1e-9


def test_back_to_back_requests_do_not_cost_stream_frames(board: EmulatedBoard, hand: Hand) -> None:
    # At 1 kHz, back to back, twice the pairs that used to cost a frame at some build ids: the
    # tick samples the stream into a ring of eight (core/hand.h), so a loop() pass that
    # answers get_state then set_targets (about 1.3 ms) only delays frames, each with its own
    # tick's board time, and the replies' traffic never starves the stream (once two samples
    # wait, the next goes out whenever the buffer has room).
    hand.set_telemetry(1000)
    hand.move([0.3] * 5, 0.2)
    hand.reset_stats()
    lost = hand.link_stats().stream_lost
    for _ in range(240):
        hand.link.request(M.GetState())
        hand.link.request(M.SetTargets(M.TargetKind.JOINT2_ANGLE, 0b11111, (0.3,) * 5))
        hand.clock.sleep(0.0077)
    assert hand.link_stats().stream_lost == lost
    assert hand.stats().tx_dropped == 0
