"""The firmware's idle sleep (loop() sleeps until an interrupt that gives it work: firmware/
README.md, "loop() and the idle sleep") on the emulated board: it sleeps, and nothing it must
do waits for the sleep: the 1 kHz stream loses no sample, a request is answered."""

from __future__ import annotations

import itertools

import pytest
from emu_helpers import LinkClient, ready_client

from utrf.emulator import EmulatedBoard
from utrf.protocol import messages as m

ALL = 0b11111
CPU_HZ = 16e6


@pytest.fixture
def client(board: EmulatedBoard) -> LinkClient:
    c = ready_client(board)[0]
    reply = c.request(
        m.SetMode(mask=ALL, mode=(m.ControlMode.DUTY,) * 5, duty=(0.3,) * 5, effort=(0.0,) * 5)
    )
    assert isinstance(reply, m.Ack), reply
    return c


def slept_share(board: EmulatedBoard, client: LinkClient, seconds: float) -> float:
    slept0, t0 = board.stats["sleep_cycles"], board.sim_time
    client.run(seconds)
    return (board.stats["sleep_cycles"] - slept0) / ((board.sim_time - t0) * CPU_HZ)


def test_an_idle_board_sleeps_most_of_the_time(board: EmulatedBoard, client: LinkClient) -> None:
    # Five fingers driven, no stream: awake for the tick, the ADC and a loop() pass or two a
    # millisecond (measured: about 60 % asleep); a loop() that spins sleeps 0 %.
    assert slept_share(board, client, 0.2) > 0.4


def test_the_1khz_stream_loses_nothing_while_the_board_sleeps(
    board: EmulatedBoard, client: LinkClient
) -> None:
    assert isinstance(client.request(m.SetTelemetry(rate_hz=1000)), m.Ack)
    client.run(0.02)
    client.stream.clear()
    assert slept_share(board, client, 0.5) > 0.05  # it does sleep between the frames
    ms = [round(s.board_time * 1000) for s in client.stream if isinstance(s, m.State)]
    assert len(ms) >= 495
    assert all((b - a) % 65536 == 1 for a, b in itertools.pairwise(ms))
    stats = client.request(m.GetStats())
    assert isinstance(stats, m.Stats)
    assert stats.tx_dropped == 0 and stats.rx_overruns == 0
    assert client.link.stats().stream_lost == 0


def test_requests_are_answered_while_the_board_sleeps(
    board: EmulatedBoard, client: LinkClient
) -> None:
    # One after another at drifting phases, each into a sleeping board: every one answered at
    # the first attempt.
    client.run(0.01)
    for k in range(50):
        pong = client.request(m.Ping(token=k))
        assert isinstance(pong, m.Pong) and pong.token == k
        client.run(0.0013)
    stats = client.link.stats()
    assert stats.retries == 0 and stats.timeouts == 0
