"""The real firmware (build/firmware/utrf.elf) on the emulated board, in simulated time: its
boot and reset cause, what it reads from the encoders, what it drives on the pins, the closed
loop through the plant, each fault injection's effect as the firmware sees it, EEPROM."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from emu_helpers import QUIET, LinkClient, ready_client

from utrf.emulator import EmulatedBoard
from utrf.protocol import messages as m

ALL = 0b11111
COAST5 = (m.ControlMode.COAST,) * 5


def set_mode(client: LinkClient, finger: int, mode: m.ControlMode, duty: float = 0.0) -> None:
    modes = list(COAST5)
    modes[finger] = mode
    duties = [0.0] * 5
    duties[finger] = duty
    reply = client.request(
        m.SetMode(mask=1 << finger, mode=tuple(modes), duty=tuple(duties), effort=(0.0,) * 5)
    )
    assert isinstance(reply, m.Ack), reply


def faults_seen(client: LinkClient, finger: int) -> m.FaultBits:
    bits = m.FaultBits(0)
    for msg in client.stream:
        if isinstance(msg, m.Fault) and msg.finger == finger:
            bits |= msg.new_faults
    return bits


@pytest.fixture
def client(board: EmulatedBoard) -> LinkClient:
    c, boot = ready_client(board)
    assert boot.reset_cause == m.ResetCause.POWER_ON
    return c


def test_boot_handshake_and_reset_cause(board: EmulatedBoard, client: LinkClient) -> None:
    identity = client.request(m.Identify())
    assert identity.protocol_version == m.PROTOCOL_VERSION
    assert identity.schema_hash == m.SCHEMA_HASH
    assert identity.reset_cause == m.ResetCause.POWER_ON
    board.reset()
    assert client.wait_boot().reset_cause == m.ResetCause.RESET_PIN
    assert client.request(m.Identify()).reset_cause == m.ResetCause.RESET_PIN


def test_the_firmware_reads_the_plant_encoders(board: EmulatedBoard, client: LinkClient) -> None:
    angles = [-1.0, -0.3, 0.2, 0.9, 1.6]
    for f, a in enumerate(angles):
        board.plant.set_theta2(f, a)
    board.run_for(0.01)
    state = client.request(m.GetState())
    # 10-bit ADC over 80 % of a turn: 7.7 mrad a count
    np.testing.assert_allclose(state.theta2, angles, atol=0.008)


def test_pins_are_what_the_firmware_drives(board: EmulatedBoard, client: LinkClient) -> None:
    set_mode(client, 1, m.ControlMode.DUTY, 0.5)
    client.run(0.2)
    state = client.request(m.GetState())
    pins = board.pins
    assert client.request(m.GetStatus()).mode[1] == m.ControlMode.DUTY
    assert state.duty_a[1] > 0.4
    assert pins.duty[1, 0] == pytest.approx(abs(state.duty_a[1]), abs=0.011)
    assert (pins.in1[1, 0], pins.in2[1, 0]) == (True, False)  # forward: pulls Tendon 1
    assert pins.duty[1, 1] == pytest.approx(abs(state.duty_b[1]), abs=0.011)
    assert pins.stby.tolist() == [False, True, False, False, False]
    assert np.all(pins.duty[[0, 2, 3, 4]] == 0.0)
    assert board.theta2[1] > 0.2  # and the finger flexed


def test_position_control_closes_the_loop_through_the_plant(
    firmware_elf: Path,
) -> None:
    with EmulatedBoard(firmware_elf, realtime=False) as board:  # gravity and noise on
        client = LinkClient(board)
        client.wait_boot()
        board.run_for(0.02)
        client.request(m.ClearFaults(mask=ALL))
        target = (0.0, 0.0, 0.8, 0.0, 0.0)
        client.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1 << 2, value=target))
        set_mode(client, 2, m.ControlMode.POSITION)
        client.run(1.0)
        assert board.theta2[2] == pytest.approx(0.8, abs=0.05)
        assert client.request(m.GetStatus()).faults[2] == m.FaultBits(0)


class TestFaultInjection:
    def test_unplugged_encoder(self, board: EmulatedBoard, client: LinkClient) -> None:
        board.unplug_encoder(3)
        client.run(0.02)
        assert m.FaultBits.ENCODER_RANGE in faults_seen(client, 3)
        assert faults_seen(client, 2) == m.FaultBits(0)

    def test_slipped_encoder_jumps(self, board: EmulatedBoard, client: LinkClient) -> None:
        board.shift_encoder(1, 0.5)  # above the firmware's 0.2 rad a tick
        client.run(0.02)
        assert m.FaultBits.ENCODER_JUMP in faults_seen(client, 1)

    def test_blocked_finger_stalls(self, board: EmulatedBoard, client: LinkClient) -> None:
        board.block_finger(0, 0.2)
        client.request(
            m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1, value=(1.0,) + (0.0,) * 4)
        )
        set_mode(client, 0, m.ControlMode.POSITION)
        client.run(0.8)
        assert board.theta2[0] == pytest.approx(0.2)
        assert m.FaultBits.STALL in faults_seen(client, 0)
        # the stall turned the motor off: no current, no tension left pulling
        assert board.motor_current[0, 0] == 0.0

    def test_line_noise_is_counted_and_survived(
        self, board: EmulatedBoard, client: LinkClient
    ) -> None:
        before = client.request(m.GetStats())
        board.inject_noise(200)  # 200 random bytes, then a clean line again
        board.run_for(0.01)
        after = client.request(m.GetStats(), timeout=0.2)
        assert (
            after.rx_crc_errors + after.rx_framing_errors
            > before.rx_crc_errors + before.rx_framing_errors
        )
        assert client.request(m.Identify()).protocol_version == m.PROTOCOL_VERSION

    def test_board_reset(self, board: EmulatedBoard, client: LinkClient) -> None:
        set_mode(client, 4, m.ControlMode.DUTY, 0.4)
        client.run(0.02)
        assert board.pins.stby[4]
        board.reset()
        boot = client.wait_boot()
        assert boot.reset_cause == m.ResetCause.RESET_PIN
        assert not board.pins.stby.any()  # all off after the reset
        assert client.request(m.GetStatus()).mode == COAST5

    def test_a_reset_that_cuts_a_frame_still_delivers_boot(self, firmware_elf: Path) -> None:
        # The board sends a lone 0x00 before boot: the state frame the reset cut off ends
        # there (one damaged frame) instead of swallowing boot, so the host learns of the reset.
        # A 250 us exchange: at the MuJoCo plant's 1 ms, one a control tick, every look falls
        # at the same phase of the 1 kHz stream and never finds the line mid-frame.
        with EmulatedBoard(
            firmware_elf, realtime=False, plant_params=QUIET, exchange_period=250e-6
        ) as board:
            client = LinkClient(board)
            assert client.wait_boot().reset_cause == m.ResetCause.POWER_ON
            self._cut_a_frame(board, client)

    @staticmethod
    def _cut_a_frame(board: EmulatedBoard, client: LinkClient) -> None:
        assert isinstance(client.request(m.SetTelemetry(rate_hz=m.MAX_TELEMETRY_HZ)), m.Ack)
        for _ in range(100):
            client.step()
            if client.tap.last_byte not in (None, 0):
                break  # the host holds part of a frame
        else:
            pytest.fail("never caught the line mid-frame")
        damaged = client.errors
        board.reset()
        assert client.wait_boot().reset_cause == m.ResetCause.RESET_PIN
        assert client.errors == damaged + 1


def test_saved_configuration_survives_in_the_eeprom_file(
    firmware_elf: Path, tmp_path: Path
) -> None:
    path = tmp_path / "eeprom.bin"
    with EmulatedBoard(firmware_elf, realtime=False, eeprom_path=path) as board:
        client = LinkClient(board)
        assert client.wait_boot().config_status == m.ConfigStatus.DEFAULTS_BLANK
        client.request(m.SetSafety(heartbeat_timeout=0.75, safe_action=m.SafeAction.COAST))
        reply = client.request(m.SaveConfig(), timeout=3.0)
        assert isinstance(reply, m.Ack)
        assert board.stats["eeprom_writes"] > 100  # at 3.4 ms a byte
    assert path.stat().st_size == 4096
    with EmulatedBoard(firmware_elf, realtime=False, eeprom_path=path) as board:
        client = LinkClient(board)
        assert client.wait_boot().config_status == m.ConfigStatus.LOADED
        safety = client.request(m.GetSafety())
        assert safety.heartbeat_timeout == pytest.approx(0.75)
        assert safety.safe_action == m.SafeAction.COAST


def test_control_tick_profile(board: EmulatedBoard, client: LinkClient) -> None:
    client.request(m.SetTelemetry(rate_hz=200))
    board.profile_interrupt("TIMER2_COMPA")
    client.run(0.2)
    prof = board.profile()["interrupt"]
    assert 195 <= prof.calls <= 201
    assert prof.period == pytest.approx(16000, rel=2e-3)
    assert 0 < prof.mean < prof.worst < 16000
    assert prof.mean_incl >= prof.mean  # the tick lets the UART and the ADC interrupt it
    stats = client.request(m.GetStats())
    assert stats.tick_overruns == 0


def test_quiet_pwm_timers_change_nothing_the_firmware_sees(firmware_elf: Path) -> None:
    """simavr's events of the PWM timers whose interrupts are off are left out
    (harness/timers.c): the firmware streams the same frames at the same times and controls
    the same way, and its tick timing from TCNT1 (timer 1 quiet too) reads the same. (Not to
    the bit: simavr ends each idle skip one cycle past the event that wakes it, so fewer
    events shift wake-ups by a few cycles, and a reading on a count's edge may differ by one
    count.)"""

    def run(quiet: bool) -> tuple[list[m.State], np.ndarray, int, m.Stats]:
        # a 250 us exchange: at the MuJoCo plant's 1 ms the run ends on a tick's edge, and a
        # wake-up a few cycles later or earlier counts one tick more or less
        with EmulatedBoard(
            firmware_elf, realtime=False, plant_params=QUIET, exchange_period=250e-6
        ) as b:
            b._native.set_quiet_timers(quiet)
            c = LinkClient(b)
            c.wait_boot()
            c.request(m.ClearFaults(mask=ALL))
            c.request(m.SetTelemetry(rate_hz=200))
            c.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=(0.5,) * 5))
            c.request(
                m.SetMode(
                    mask=ALL, mode=(m.ControlMode.POSITION,) * 5, duty=(0.0,) * 5,
                    effort=(0.0,) * 5,
                )
            )  # fmt: skip
            c.run(1.0)
            states = [s for s in c.stream if isinstance(s, m.State)]
            return states, b.theta2.copy(), b.stats["quieted_timer_events"], c.request(m.GetStats())

    (quiet, th_q, n_q, fw_q), (loud, th_l, n_l, fw_l) = run(True), run(False)
    assert n_q > 0 and n_l == 0
    # the tick's own timing, from TCNT1 and TCNT2: a stale count would put it off by periods
    assert fw_q.ticks == fw_l.ticks and fw_q.tick_overruns == fw_l.tick_overruns == 0
    assert abs(fw_q.tick_worst - fw_l.tick_worst) <= 2e-6
    assert abs(fw_q.tick_mean - fw_l.tick_mean) <= 2e-6
    assert [s.board_time for s in quiet] == [s.board_time for s in loud]  # same frames, times
    count = 2 * np.pi / (1024 * 0.8)  # one ADC count of Joint 2 (80 % of a turn): 7.7 mrad
    diff = np.array([np.subtract(a.theta2, b.theta2) for a, b in zip(quiet, loud, strict=True)])
    assert np.abs(diff).max() <= count * 1.01
    np.testing.assert_allclose(th_q, th_l, atol=0.01)
    np.testing.assert_allclose(th_q, 0.5, atol=0.03)  # both reached the targets


def test_simlink_looks_at_the_output_per_frame(firmware_elf: Path) -> None:
    """Driven, SimLink runs the board in C from one frame to the next
    (``run_until_output``): one crossing per frame and heartbeat, not one per millisecond."""
    from utrf.hand.simlink import SimLink

    with EmulatedBoard(firmware_elf, realtime=False, plant_params=QUIET) as board:
        got: list[float] = []
        link = SimLink(
            board, on_telemetry=lambda t: got.append(t.received_s)
            if isinstance(t.message, m.State) else None,
        )  # fmt: skip
        link.handshake()
        link.request(m.SetTelemetry(rate_hz=100))
        link.sleep(0.05)
        native = board._native
        calls = [0]
        run = native.run_plant_until

        def counted(*args: int) -> int:
            calls[0] += 1
            return run(*args)

        native.run_plant_until = counted  # type: ignore[method-assign]
        got.clear()
        link.sleep(1.0)
        assert 99 <= len(got) <= 101  # the 100 Hz stream, every frame delivered
        assert len(got) <= calls[0] < 1.5 * len(got)  # plus heartbeats' acks, not 1000
