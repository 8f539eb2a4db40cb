"""The lingering reader (``SerialTransport.linger_s``, ``Link.read_linger_s``): one read
carries what arrived during the linger, and a request's reply is read as soon as it comes
whatever the linger."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest
from fake_board import FakeBoard, state_sample

from utrf.protocol import messages as M
from utrf.protocol.link import Link
from utrf.protocol.transport import SerialTransport


@pytest.fixture
def board() -> Iterator[FakeBoard]:
    b = FakeBoard()
    yield b
    b.close()


def test_a_lingering_reader_takes_what_came_meanwhile_in_one_read() -> None:
    got: list[bytes] = []
    transport = SerialTransport("loop://", linger_s=0.1)
    transport.start(got.append, lambda exc: None)
    try:
        transport.write(b"\x01")
        deadline = time.monotonic() + 1.0
        while not got and time.monotonic() < deadline:
            time.sleep(0.001)
        for byte in (b"\x02", b"\x03", b"\x04"):  # while the reader lingers
            transport.write(byte)
            time.sleep(0.001)
        deadline = time.monotonic() + 1.0
        while b"".join(got) != b"\x01\x02\x03\x04" and time.monotonic() < deadline:
            time.sleep(0.005)
        assert got == [b"\x01", b"\x02\x03\x04"]
    finally:
        transport.close()


def test_a_reply_is_read_at_once_while_the_reader_lingers(board: FakeBoard) -> None:
    with Link.open(board.url, heartbeat_period_s=None, telemetry_queue_size=64) as link:
        link.read_linger_s = 0.1
        waits = []
        for k in range(5):
            board.emit(state_sample(1.0 + k))
            link.telemetry.get(timeout=1.0)  # read: the reader now lingers 0.1 s
            t0 = time.monotonic()
            assert link.request(M.Ping(k)).token == k
            waits.append(time.monotonic() - t0)
        # a reply left to the end of the linger would take at least 0.1 s less the time the
        # sample took from the reader to here
        assert min(waits) < 0.06, waits


def test_a_lingering_link_loses_no_frame(board: FakeBoard) -> None:
    with Link.open(board.url, heartbeat_period_s=None, telemetry_queue_size=256) as link:
        link.read_linger_s = 0.02

        def stream() -> None:
            for i in range(100):
                board.emit(state_sample(1.0 + i * 0.001))
                time.sleep(0.0005)

        thread = threading.Thread(target=stream)
        thread.start()
        tokens = [link.request(M.Ping(k)).token for k in range(5)]  # replies amid the stream
        thread.join()
        items = [link.telemetry.get(timeout=1.0) for _ in range(100)]
        assert tokens == list(range(5))
        assert [it.message.board_time for it in items] == [
            state_sample(1.0 + i * 0.001).board_time for i in range(100)
        ]
        assert link.stats().stream_lost == 0


@pytest.mark.parametrize("bad", [-0.001, 0.2])
def test_a_linger_out_of_range_is_refused(bad: float) -> None:
    transport = SerialTransport("loop://")
    try:
        with pytest.raises(ValueError, match=r"linger_s must lie in 0\.\.0\.1 s"):
            transport.linger_s = bad
        assert transport.linger_s == 0.0
    finally:
        transport.close()


def test_read_soon_ends_the_linger_and_skips_the_next() -> None:
    got: list[tuple[float, bytes]] = []
    transport = SerialTransport("loop://", linger_s=0.1)
    transport.start(lambda data: got.append((time.monotonic(), data)), lambda exc: None)
    try:
        transport.write(b"\x01")
        deadline = time.monotonic() + 1.0
        while not got and time.monotonic() < deadline:
            time.sleep(0.001)
        time.sleep(0.01)  # the reader now lingers 0.1 s
        t0 = time.monotonic()
        transport.read_soon()  # nothing came yet: what comes next is handed on at once
        time.sleep(0.01)
        transport.write(b"\x02")
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.001)
        assert got[1][1] == b"\x02" and got[1][0] - t0 < 0.06
        transport.write(b"\x03")  # the wish was answered: the reader lingers again
        time.sleep(0.03)
        assert len(got) == 2
    finally:
        transport.close()
