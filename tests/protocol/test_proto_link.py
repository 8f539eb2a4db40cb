"""Link against a scripted fake board over TCP (socket://): matching by seq, retries,
timeouts, nacks, the handshake, resets, disconnects and telemetry."""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fake_board import FakeBoard, Handler, Reply, identity, state_sample

from utrf.protocol import messages as M
from utrf.protocol.errors import (
    BoardResetError,
    DisconnectedError,
    NackError,
    ProtocolError,
    ReplyTimeout,
    SchemaMismatchError,
)
from utrf.protocol.framing import Frame
from utrf.protocol.link import Link, Telemetry
from utrf.protocol.transport import SerialTransport

TARGETS = M.SetTargets(M.TargetKind.JOINT2_ANGLE, 0b11111, (0.1, 0.2, 0.3, 0.4, 0.5))


@pytest.fixture
def board() -> Iterator[FakeBoard]:
    b = FakeBoard()
    yield b
    b.close()


@pytest.fixture
def link(board: FakeBoard) -> Iterator[Link]:
    with Link.open(board.url, heartbeat_period_s=None) as lk:
        yield lk


def test_handshake_returns_the_identity(link: Link) -> None:
    got = link.handshake()
    assert got == identity()
    assert link.identity == got


def test_handshake_names_both_versions_and_hashes_on_mismatch(board: FakeBoard, link: Link) -> None:
    # Firmware of protocol version 2, whose identity is longer: only its head is read.
    other = identity(version=2, schema=0xDEADBEEF).encode() + b"\x01\x02\x03"
    board.on(M.Identify.ID, lambda f: [(f.seq, (M.Identity.ID, other))])
    with pytest.raises(SchemaMismatchError) as info:
        link.handshake()
    text = str(info.value)
    assert f"version {M.PROTOCOL_VERSION} (schema 0x{M.SCHEMA_HASH:08X})" in text
    assert "version 2 (schema 0xDEADBEEF)" in text
    assert (info.value.board_version, info.value.board_hash) == (2, 0xDEADBEEF)
    assert link.identity is None


def test_replies_are_matched_by_seq_and_stale_ones_ignored(board: FakeBoard, link: Link) -> None:
    def late_then_right(frame: Frame) -> Reply:
        stale = (frame.seq + 5) & 0x7F  # a reply to some other request
        return [
            (stale, M.Pong(999, 1.0)),
            (frame.seq, M.Pong(M.Ping.decode(frame.body).token, 2.0)),
        ]

    board.on(M.Ping.ID, late_then_right)
    for token in (1, 0xFFFFFFFF, 42):
        assert link.request(M.Ping(token)).token == token
    assert link.stats().stale_replies == 3
    gains = link.request(M.GetGains(finger=3))
    assert isinstance(gains, M.Gains) and gains.finger == 3
    seqs = [f.seq for f in board.received]
    assert len(set(seqs)) == len(seqs) and all(s < M.BOARD_SEQ_FLAG for s in seqs)


def test_idempotent_request_is_resent_with_the_same_seq(board: FakeBoard, link: Link) -> None:
    board.on(M.SetTargets.ID, _drop_then_default(board, 2))
    assert link.request(TARGETS, timeout_s=0.05) == M.Ack(M.SetTargets.ID)
    copies = [f for f in board.received if f.msg_id == M.SetTargets.ID]
    assert len(copies) == 3
    assert len({(f.seq, f.body) for f in copies}) == 1
    assert link.stats().retries == 2


def _drop_then_default(board: FakeBoard, times: int) -> Handler:
    """Ignore the first `times` frames (lost requests), then answer as the board would."""
    seen = {"n": 0}

    def handler(frame: Frame) -> Reply:
        seen["n"] += 1
        return None if seen["n"] <= times else board.default(frame)

    return handler


def test_timeout_after_every_retry(board: FakeBoard, link: Link) -> None:
    board.on(M.Ping.ID, lambda f: None)
    start = time.monotonic()
    with pytest.raises(ReplyTimeout, match="no reply to ping after 3 attempt") as info:
        link.request(M.Ping(1), timeout_s=0.05, retries=2)
    elapsed = time.monotonic() - start
    assert info.value.attempts == 3
    assert 0.15 <= elapsed < 1.0
    assert board.count(M.Ping.ID) == 3
    assert link.stats().timeouts == 1


def test_request_that_is_not_idempotent_is_never_resent(board: FakeBoard, link: Link) -> None:
    board.on(M.CalibrateZero.ID, lambda f: None)
    with pytest.raises(ReplyTimeout) as info:
        link.request(M.CalibrateZero(mask=1), timeout_s=0.05)
    assert info.value.attempts == 1
    time.sleep(0.1)
    assert board.count(M.CalibrateZero.ID) == 1


def test_nack_raises_with_its_code_detail_and_request(board: FakeBoard, link: Link) -> None:
    board.on(M.SetMode.ID, lambda f: [(f.seq, M.Nack(M.SetMode.ID, M.ErrorCode.OUT_OF_RANGE, 2))])
    request = M.SetMode(1, (M.ControlMode.DUTY,) * 5, (0.5,) * 5, (0.0,) * 5)
    with pytest.raises(NackError) as info:
        link.request(request)
    assert info.value.code is M.ErrorCode.OUT_OF_RANGE
    assert info.value.detail == 2
    assert info.value.request == request
    assert "set_mode refused: OUT_OF_RANGE (detail 2): field duty" in str(info.value)
    assert board.count(M.SetMode.ID) == 1  # a refusal is an answer: no retry


def test_bad_crc_nack_makes_an_idempotent_request_resend_at_once(
    board: FakeBoard, link: Link
) -> None:
    seen = {"n": 0}

    def first_damaged(frame: Frame) -> Reply:
        seen["n"] += 1
        if seen["n"] == 1:
            return [(frame.seq, M.Nack(frame.msg_id, M.ErrorCode.BAD_CRC, 0))]
        return [(frame.seq, M.Ack(frame.msg_id))]

    board.on(M.SetTargets.ID, first_damaged)
    start = time.monotonic()
    assert link.request(TARGETS, timeout_s=1.0) == M.Ack(M.SetTargets.ID)
    assert time.monotonic() - start < 0.5  # resent on the hint, not after the 1 s timeout
    assert board.count(M.SetTargets.ID) == 2


def test_bad_crc_nack_ends_a_request_only_when_it_names_it(board: FakeBoard, link: Link) -> None:
    # Another frame's damage (wrong seq): a hint only; the real ack still counts.
    board.on(
        M.CalibrateZero.ID,
        lambda f: [
            ((f.seq + 1) & 0x7F, M.Nack(0x33, M.ErrorCode.BAD_CRC, 0)),
            (f.seq, M.Ack(M.CalibrateZero.ID)),
        ],
    )
    assert link.request(M.CalibrateZero(mask=1)) == M.Ack(M.CalibrateZero.ID)
    # Naming this very request (seq and id): the board did not run it.
    board.on(M.CalibrateZero.ID, lambda f: [(f.seq, M.Nack(f.msg_id, M.ErrorCode.BAD_CRC, 0))])
    with pytest.raises(NackError) as info:
        link.request(M.CalibrateZero(mask=1))
    assert info.value.code is M.ErrorCode.BAD_CRC
    # Idempotent and named every time: resent until the attempts run out, then refused.
    board.on(M.SetTargets.ID, lambda f: [(f.seq, M.Nack(f.msg_id, M.ErrorCode.BAD_CRC, 0))])
    with pytest.raises(NackError):
        link.request(TARGETS, retries=2)
    assert board.count(M.SetTargets.ID) == 3


def test_telemetry_flows_while_a_request_waits(board: FakeBoard) -> None:
    arrivals: list[float] = []
    reply_sent = threading.Event()

    def slow_save(frame: Frame) -> Reply:
        def work() -> None:
            for i in range(20):
                board.emit(state_sample(1.0 + i * 0.002))
                time.sleep(0.005)
            reply_sent.set()
            board.reply(frame.seq, M.Ack(M.SaveConfig.ID))

        threading.Thread(target=work, daemon=True).start()
        return None

    board.on(M.SaveConfig.ID, slow_save)
    with Link.open(
        board.url, heartbeat_period_s=None, on_telemetry=lambda t: arrivals.append(time.monotonic())
    ) as link:
        assert link.request(M.SaveConfig()) == M.Ack(M.SaveConfig.ID)
        done = time.monotonic()
        items = [link.telemetry.get(timeout=1.0) for _ in range(20)]
    assert all(isinstance(t, Telemetry) and isinstance(t.message, M.State) for t in items)
    assert [t.message.board_time for t in items] == pytest.approx(
        [1.0 + i * 0.002 for i in range(20)]
    )
    assert len(arrivals) == 20 and max(arrivals) <= done  # all delivered before the reply
    assert link.stats().stream_lost == 0


def test_gaps_in_stream_seqs_count_as_lost(board: FakeBoard, link: Link) -> None:
    got: list[int] = []
    link.add_telemetry_callback(lambda t: got.append(t.seq))
    board.emit(state_sample())  # 0x80
    board.emit(state_sample())  # 0x81
    board.emit(state_sample(), skip=1)  # 0x83: one lost
    board.emit(M.Fault(1.0, 2, M.FaultBits.STALL, (0, 0, 4, 0, 0)), skip=2)  # 0x86: two lost
    link.request(M.Ping(7))  # the reply comes after the four frames
    assert got == [0x80, 0x81, 0x83, 0x86]
    assert link.stats().stream_lost == 3
    assert link.stats().stream_frames == 4


def test_get_state_reply_goes_to_the_caller_not_the_stream(board: FakeBoard, link: Link) -> None:
    board.emit(state_sample(5.0))
    reply = link.request(M.GetState())
    assert reply == state_sample()
    board.emit(state_sample(6.0))
    link.request(M.Ping(1))
    stream = [link.telemetry.get(timeout=1.0).message.board_time for _ in range(2)]
    assert stream == [5.0, 6.0]
    assert link.telemetry.empty()
    assert link.stats().stream_lost == 0


def test_boot_fails_the_waiting_request_and_every_next_one_until_handshake(
    board: FakeBoard, link: Link
) -> None:
    link.handshake()
    board.on(M.SetTargets.ID, lambda f: board.boot() or None)
    with pytest.raises(BoardResetError, match="WATCHDOG"):
        link.request(TARGETS)
    with pytest.raises(BoardResetError):
        link.request(M.Ping(1))
    assert link.identity is None
    boot = link.telemetry.get(timeout=1.0)
    assert isinstance(boot.message, M.Boot) and boot.seq == M.BOARD_SEQ_FLAG
    assert link.handshake() == identity()
    assert link.request(M.Ping(2)).token == 2


def test_disconnect_fails_the_waiting_request_and_the_next(board: FakeBoard, link: Link) -> None:
    board.on(M.Ping.ID, lambda f: board.disconnect() or None)
    with pytest.raises(DisconnectedError, match="line went away"):
        link.request(M.Ping(1), timeout_s=2.0)
    with pytest.raises(DisconnectedError):
        link.request(M.Ping(2))


def test_heartbeats_go_out_when_idle_after_the_handshake(board: FakeBoard) -> None:
    with Link.open(board.url, heartbeat_period_s=0.03) as link:
        time.sleep(0.15)
        assert board.count(M.Heartbeat.ID) == 0  # not before the handshake
        link.handshake()
        assert board.wait_for(M.Heartbeat.ID, 3, timeout=1.0)
        # Busy with requests: no heartbeat is needed.
        before = board.count(M.Heartbeat.ID)
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            link.request(M.Ping(1))
        assert board.count(M.Heartbeat.ID) <= before + 1
        stats = link.stats()
    assert stats.heartbeats >= 3
    assert stats.stale_replies == 0  # their acks are absorbed


def test_requests_from_many_threads_each_get_their_own_reply(link: Link) -> None:
    results: dict[int, int] = {}

    def worker(k: int) -> None:
        for i in range(20):
            token = k * 1000 + i
            results[token] = link.request(M.Ping(token)).token

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert len(results) == 80 and all(k == v for k, v in results.items())


def test_invalid_request_raises_before_anything_is_sent(board: FakeBoard, link: Link) -> None:
    with pytest.raises(ValueError, match=r"set_telemetry\.rate_hz: 1001 is outside"):
        link.request(M.SetTelemetry(rate_hz=1001))
    with pytest.raises(TypeError, match="Pong is not a request"):
        link.request(M.Pong(1, 0.0))  # type: ignore[arg-type]
    link.request(M.Ping(1))
    assert [f.msg_id for f in board.received] == [M.Ping.ID]


def test_wrong_or_corrupt_reply_is_an_error_not_a_message(board: FakeBoard, link: Link) -> None:
    board.on(M.GetGains.ID, lambda f: [(f.seq, M.Ack(M.GetGains.ID))])
    with pytest.raises(ProtocolError, match="get_gains was answered with ack, expected gains"):
        link.request(M.GetGains(finger=0))
    board.on(M.GetGains.ID, lambda f: [(f.seq, (M.Gains.ID, b"\x09" + bytes(26)))])
    with pytest.raises(ProtocolError, match=r"^gains\.finger: 9 is outside \[0, 4\]"):
        link.request(M.GetGains(finger=0))


def test_closed_link_refuses_requests(board: FakeBoard) -> None:
    link = Link.open(board.url, heartbeat_period_s=None)
    link.close()
    with pytest.raises(DisconnectedError, match="closed"):
        link.request(M.Ping(1))


def test_transport_over_loop_url_and_a_bad_url() -> None:
    got: list[bytes] = []
    closed = threading.Event()
    transport = SerialTransport("loop://")
    transport.start(got.append, lambda exc: closed.set())
    transport.write(b"\x01\x02\x00")
    deadline = time.monotonic() + 1.0
    while b"".join(got) != b"\x01\x02\x00" and time.monotonic() < deadline:
        time.sleep(0.005)
    assert b"".join(got) == b"\x01\x02\x00"
    transport.close()
    assert closed.wait(1.0)
    with pytest.raises(DisconnectedError, match=r"cannot open 'socket://127\.0\.0\.1:1'"):
        SerialTransport("socket://127.0.0.1:1")


def test_the_readme_example_runs(board: FakeBoard) -> None:
    readme = (Path(__file__).resolve().parents[2] / "protocol" / "README.md").read_text()
    code = re.search(r"```python\n(.*?)```", readme, re.S)
    assert code is not None

    def start_stream(frame: Frame) -> Reply:
        threading.Timer(0.01, lambda: board.emit(state_sample(3.0))).start()
        return [(frame.seq, M.Ack(frame.msg_id))]

    board.on(M.SetTelemetry.ID, start_stream)
    namespace: dict[str, object] = {}
    exec(code.group(1).replace("socket://127.0.0.1:5555", board.url), namespace)
    assert namespace["sample"] == state_sample(3.0)
    sent = [f.msg_id for f in board.received if f.msg_id != M.Heartbeat.ID]
    assert sent == [M.Identify.ID, M.SetTelemetry.ID, M.SetTargets.ID]
