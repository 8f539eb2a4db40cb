"""The real firmware against the chip's receiver as the harness models it (a two-byte FIFO
behind the shift register, DOR0, FE0): lost bytes are counted in the board's stats and the
damaged frame is dropped; ordinary traffic loses none."""

from __future__ import annotations

import pytest
from emu_helpers import LinkClient, ready_client

from utrf.emulator import EmulatedBoard
from utrf.protocol import messages as m
from utrf.protocol.framing import encode_frame

ALL = 0b11111
FRAME_CYCLES = 160  # 8N1 at 1 Mbaud


@pytest.fixture
def client(board: EmulatedBoard) -> LinkClient:
    return ready_client(board)[0]


def hold_at_zero(client: LinkClient) -> None:
    """Every finger in POSITION at 0 rad."""
    targets = m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=(0.0,) * 5)
    assert isinstance(client.request(targets), m.Ack)
    mode = m.SetMode(
        mask=ALL, mode=(m.ControlMode.POSITION,) * 5, duty=(0.0,) * 5, effort=(0.0,) * 5
    )
    assert isinstance(client.request(mode), m.Ack)
    client.run(0.02)


def test_a_slow_receive_interrupt_overruns_and_the_frame_is_dropped(
    board: EmulatedBoard, client: LinkClient
) -> None:
    """The receive interrupt stalls 100 µs (ten byte times) at the first byte of a set_targets
    frame: the chip keeps two bytes and the shift register's, the rest are lost (DOR0), the
    board counts the overrun, drops the frame (no ack, targets unchanged) and answers the
    next request."""
    hold_at_zero(client)
    assert isinstance(client.request(m.ResetStats()), m.Ack)
    lost0 = board.stats["rx_overruns"]
    far = m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=(0.6,) * 5)
    frame = encode_frame(0x33, far.ID, far.encode())  # written raw: the client would resend it
    board.stall_interrupt("USART0_RX", 100e-6, count=1)
    board.write(frame)
    client.run(0.05)
    assert board.stats["stalls"] == 1
    lost = board.stats["rx_overruns"] - lost0
    assert 6 <= lost <= 10  # about ten byte times, less the FIFO's two and the shift register
    stats = client.request(m.GetStats())
    assert isinstance(stats, m.Stats)
    assert stats.uart_overruns == 1  # one DOR0: one or more bytes lost before the byte read
    assert stats.uart_frame_errors == 0
    assert stats.rx_crc_errors + stats.rx_framing_errors == 1  # the damaged frame, dropped
    assert not any(isinstance(f, m.Ack) and f.msg_id == far.ID for f in client.stream)
    state = client.request(m.GetState())
    assert isinstance(state, m.State)
    assert max(abs(t) for t in state.target) < 1e-3  # no finger was sent anywhere
    assert max(abs(a) for a in board.theta2) < 0.05


def test_line_noise_is_counted_as_frame_errors(firmware_elf) -> None:
    """Noise bytes on the line (inserted, random stop bits): the firmware's FE0 count is the
    harness's, byte for byte, and no byte is lost to an overrun."""
    with EmulatedBoard(firmware_elf, realtime=False, seed=3) as board:
        client, _ = ready_client(board)
        assert isinstance(client.request(m.ResetStats()), m.Ack)
        fe0 = board.stats["rx_frame_errors"]
        board.set_line_faults("to_board", insert=0.05)
        for _ in range(40):
            client.request(m.Ping(token=7))
        board.set_line_faults("to_board")
        noisy = board.stats["rx_frame_errors"] - fe0
        stats = client.request(m.GetStats())
        assert isinstance(stats, m.Stats)
        assert noisy > 0
        assert stats.uart_frame_errors == noisy
        assert stats.uart_overruns == 0 and board.stats["rx_overruns"] == 0


def test_requests_one_at_a_time_with_the_stream_lose_no_byte(
    board: EmulatedBoard, client: LinkClient
) -> None:
    """Normal traffic (the 1 kHz stream on, set_targets and pings one at a time, as the Hand
    sends them): no byte lost, none read later than the chip's two-byte FIFO allows.
    (Requests back to back, the line saturated, do lose some: docs/benchmarks.md.)"""
    hold_at_zero(client)
    assert isinstance(client.request(m.SetTelemetry(rate_hz=1000)), m.Ack)
    board.rx_timing(clear=True)
    for k in range(150):
        v = 0.2 if k & 1 else -0.2
        req = m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=(v,) * 5)
        assert isinstance(client.request(req if k % 3 else m.Ping(token=k)), (m.Ack, m.Pong))
        client.run(0.0007)
    rx = board.rx_timing()
    assert rx["reads"] > 3000 and rx["overruns"] == 0
    assert rx["worst"] < 2 * FRAME_CYCLES
    stats = client.request(m.GetStats())
    assert isinstance(stats, m.Stats)
    assert (stats.uart_overruns, stats.uart_frame_errors, stats.rx_overruns) == (0, 0, 0)
