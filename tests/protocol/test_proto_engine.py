"""The protocol engine on its own: no thread, no clock, no line. Each test plays the board by
hand (frames fed in at chosen times) and checks what the engine asks to send and when."""

from __future__ import annotations

import pytest
from fake_board import identity, state_sample

from utrf.protocol import messages as M
from utrf.protocol.codec import Message
from utrf.protocol.engine import Done, Engine, Kind, Telemetry, Transmit, Wait
from utrf.protocol.errors import (
    BoardResetError,
    DisconnectedError,
    NackError,
    Outcome,
    ProtocolError,
    ReplyTimeout,
    SchemaMismatchError,
)
from utrf.protocol.framing import decode_stream, encode_frame

TARGETS = M.SetTargets(M.TargetKind.JOINT2_ANGLE, 0b11111, (0.1, 0.2, 0.3, 0.4, 0.5))
T = M.SetTargets.REPLY_TIMEOUT_S  # 0.1 s


def frame(seq: int, msg: Message) -> bytes:
    return encode_frame(seq, msg.ID, msg.encode())


def bad_crc(msg_id: int) -> M.Nack:
    """The board's answer to a damaged frame whose (maybe damaged) id reads ``msg_id``."""
    return M.Nack(msg_id, M.ErrorCode.BAD_CRC, 0)


def send(engine: Engine, now: float) -> Transmit:
    """Poll, expect something to write, and report it written at ``now``."""
    action = engine.poll(now)
    assert isinstance(action, Transmit), action
    engine.sent(action, now)
    return action


def seq_of(tx: Transmit) -> int:
    (decoded,) = decode_stream(tx.data)
    return decoded.seq  # type: ignore[union-attr]


def start(engine: Engine, msg: Message, now: float = 0.0, **kwargs: object) -> int:
    """Start a request, write its first attempt at ``now``; returns its seq."""
    engine.start_request(msg, **kwargs)  # type: ignore[arg-type]
    return seq_of(send(engine, now))


def shake_hands(engine: Engine, now: float = 0.0) -> None:
    engine.start_handshake(3.0, now)
    assert send(engine, now).kind is Kind.DELIMITER
    seq = seq_of(send(engine, now))
    engine.receive(frame(seq, identity()), now)
    assert engine.poll(now) == Done(identity())


def test_a_request_waits_for_its_reply_until_its_timeout() -> None:
    engine = Engine()
    engine.start_request(M.Ping(7))
    tx = send(engine, 1.0)
    assert tx.kind is Kind.REQUEST and tx.data == frame(0, M.Ping(7))
    assert engine.poll(1.05) == Wait(1.0 + T)
    assert not engine.settled
    assert engine.receive(frame(0, M.Pong(7, 2.0)), 1.06) == []
    assert engine.settled
    done = engine.poll(1.06)
    assert isinstance(done, Done) and M.Pong.decode(done.result().body) == M.Pong(7, 2.0)
    stats = engine.stats()
    assert (stats.tx_frames, stats.rx_frames, stats.retries, stats.stale_replies) == (1, 1, 0, 0)


def test_seqs_count_up_to_127_then_wrap() -> None:
    engine = Engine()
    seqs = []
    for i in range(130):
        seqs.append(start(engine, M.Ping(i), float(i)))
        engine.receive(frame(seqs[-1], M.Pong(i, 0.0)), float(i))
        assert isinstance(engine.poll(float(i)), Done)
    assert seqs == [*range(128), 0, 1]


def test_an_idempotent_request_is_resent_at_its_timeout_then_given_up() -> None:
    engine = Engine(retries=2)
    seq = start(engine, TARGETS, 0.0)
    assert engine.poll(T - 1e-9) == Wait(T)
    resent = send(engine, T)  # the deadline itself: resend, same seq and bytes
    assert resent.data == frame(seq, TARGETS)
    assert engine.poll(T + 0.01) == Wait(2 * T)
    send(engine, 2 * T)
    done = engine.poll(3 * T)
    assert isinstance(done, Done) and isinstance(done.error, ReplyTimeout)
    assert done.error.attempts == 3 and done.error.request == TARGETS
    with pytest.raises(ReplyTimeout, match="no reply to set_targets after 3 attempt"):
        done.result()
    stats = engine.stats()
    assert (stats.tx_frames, stats.retries, stats.timeouts) == (3, 2, 1)


def test_a_request_that_is_not_idempotent_is_never_resent() -> None:
    engine = Engine(retries=3)
    start(engine, M.CalibrateZero(mask=1), 0.0)
    done = engine.poll(T)
    assert isinstance(done, Done) and isinstance(done.error, ReplyTimeout)
    assert done.error.attempts == 1 and engine.stats().tx_frames == 1


def test_per_request_timeout_and_retries() -> None:
    engine = Engine()
    start(engine, M.Ping(1), 0.0, timeout_s=0.5, retries=0)
    assert engine.poll(0.4) == Wait(0.5)
    done = engine.poll(0.5)
    assert isinstance(done, Done) and done.error.attempts == 1  # type: ignore[union-attr]


def test_a_reply_arriving_after_a_resend_ends_the_request_and_its_twin_is_stale() -> None:
    engine = Engine()
    seq = start(engine, TARGETS, 0.0)
    send(engine, T)  # resent: the first reply was late, not lost
    engine.receive(frame(seq, M.Ack(TARGETS.ID)), T + 0.001)
    done = engine.poll(T + 0.001)
    assert isinstance(done, Done) and M.Ack.decode(done.result().body) == M.Ack(TARGETS.ID)
    engine.receive(frame(seq, M.Ack(TARGETS.ID)), T + 0.002)  # the resend's own reply
    assert engine.stats().stale_replies == 1


def test_replies_to_other_seqs_or_other_requests_are_stale() -> None:
    engine = Engine()
    seq = start(engine, TARGETS, 0.0)
    engine.receive(frame((seq + 5) & 0x7F, M.Ack(TARGETS.ID)), 0.01)  # another seq
    engine.receive(frame(seq, M.Ack(M.SetMode.ID)), 0.01)  # acks another message
    assert engine.poll(0.01) == Wait(T)
    assert engine.stats().stale_replies == 2


def test_a_nack_ends_the_request_with_its_code_and_detail() -> None:
    engine = Engine()
    seq = start(engine, TARGETS, 0.0)
    engine.receive(frame(seq, M.Nack(TARGETS.ID, M.ErrorCode.OUT_OF_RANGE, 0x82)), 0.01)
    done = engine.poll(0.01)
    assert isinstance(done, Done) and isinstance(done.error, NackError)
    assert (done.error.code, done.error.detail) == (M.ErrorCode.OUT_OF_RANGE, 0x82)
    assert "finger 2 is outside its limits" in str(done.error)
    assert engine.stats().nacks == 1 and engine.stats().retries == 0


def test_a_wrong_reply_is_an_error() -> None:
    engine = Engine()
    seq = start(engine, M.GetGains(finger=0), 0.0)
    engine.receive(frame(seq, M.Ack(M.GetGains.ID)), 0.01)
    done = engine.poll(0.01)
    assert isinstance(done, Done) and isinstance(done.error, ProtocolError)
    assert str(done.error) == "get_gains was answered with ack, expected gains"


def test_a_bad_crc_hint_resends_an_idempotent_request_at_once() -> None:
    engine = Engine(retries=1)
    seq = start(engine, TARGETS, 0.0)
    engine.receive(frame(seq, bad_crc(TARGETS.ID)), 0.01)
    assert engine.settled
    resent = send(engine, 0.01)  # long before the timeout
    assert seq_of(resent) == seq and engine.stats().retries == 1
    assert engine.poll(0.02) == Wait(0.01 + T)  # the timeout runs from the resend
    # No attempt left: a hint about another frame keeps it waiting ...
    engine.receive(frame((seq + 1) & 0x7F, bad_crc(TARGETS.ID)), 0.03)
    assert engine.poll(0.03) == Wait(0.01 + T)
    # ... and one naming this very request ends it.
    engine.receive(frame(seq, bad_crc(TARGETS.ID)), 0.04)
    done = engine.poll(0.04)
    assert isinstance(done, Done) and isinstance(done.error, NackError)
    assert done.error.code is M.ErrorCode.BAD_CRC


def test_bad_crc_hints_do_not_spend_the_resends_of_the_timeouts() -> None:
    # A burst of damage answers attempt after attempt with BAD_CRC within milliseconds; the
    # request keeps its resends after a timeout (at 1e-2 damaged bytes four hints once spent
    # half of them and a set_gains failed after 0.5 s).
    engine = Engine(retries=2)
    seq = start(engine, TARGETS, 0.0)
    for k in range(2):  # two hints: two resends at once
        engine.receive(frame(seq, bad_crc(TARGETS.ID)), 0.01 * (k + 1))
        assert seq_of(send(engine, 0.01 * (k + 1))) == seq
    engine.receive(frame(seq, bad_crc(M.SetMode.ID)), 0.03)  # no hint's resend left: waits
    assert engine.poll(0.03) == Wait(0.02 + T)
    t = 0.02 + T
    for _ in range(2):  # the timeouts' two resends are still there
        assert seq_of(send(engine, t)) == seq
        t += T
    done = engine.poll(t)
    assert isinstance(done, Done) and isinstance(done.error, ReplyTimeout)
    assert done.error.attempts == 5  # the first, two on hints, two on timeouts
    assert engine.stats().retries == 4


def test_a_bad_crc_hint_ends_a_request_that_is_not_idempotent_only_when_it_names_it() -> None:
    engine = Engine()
    seq = start(engine, M.CalibrateZero(mask=1), 0.0)
    engine.receive(frame((seq + 1) & 0x7F, bad_crc(M.CalibrateZero.ID)), 0.01)
    assert engine.poll(0.01) == Wait(T)  # another frame's damage: ignored, not resent
    assert engine.stats().stale_replies == 0
    engine.receive(frame(seq, bad_crc(M.CalibrateZero.ID)), 0.02)
    done = engine.poll(0.02)
    assert isinstance(done, Done) and isinstance(done.error, NackError)
    assert engine.stats().tx_frames == 1


def test_a_boot_mid_request_fails_it_and_every_next_one_until_the_handshake() -> None:
    engine = Engine()
    shake_hands(engine)
    start(engine, TARGETS, 1.0)
    boot = M.Boot(M.PROTOCOL_VERSION, M.SCHEMA_HASH, M.ResetCause.WATCHDOG, M.ConfigStatus.LOADED)
    items = engine.receive(frame(M.BOARD_SEQ_FLAG, boot), 1.01)
    assert items == [Telemetry(boot, M.BOARD_SEQ_FLAG, 1.01)]
    done = engine.poll(1.01)
    assert isinstance(done, Done) and isinstance(done.error, BoardResetError)
    assert "WATCHDOG" in str(done.error) and engine.identity is None
    with pytest.raises(BoardResetError):
        engine.start_request(M.Ping(1))
    assert engine.heartbeat_due() is None  # no heartbeats to a board that lost its state
    shake_hands(engine, 2.0)
    start(engine, M.Ping(2), 2.0)  # usable again


def test_the_handshake_asks_again_until_its_deadline_with_a_new_seq_each_time() -> None:
    engine = Engine()
    engine.start_handshake(0.25, 10.0)
    assert send(engine, 10.0).data == b"\x00"  # ends whatever partial frame the board holds
    seqs = [seq_of(send(engine, 10.0))]
    assert engine.poll(10.05) == Wait(10.0 + T)
    seqs.append(seq_of(send(engine, 10.1)))
    seqs.append(seq_of(send(engine, 10.2)))
    assert engine.poll(10.2) == Wait(10.25)  # the last attempt is cut to what is left
    done = engine.poll(10.25)
    assert isinstance(done, Done) and isinstance(done.error, ReplyTimeout)
    assert done.error.attempts == 3 and seqs == [0, 1, 2]
    assert engine.stats().retries == 0  # each attempt is a request of its own


def test_the_handshake_rides_out_a_boot_and_clears_an_old_one() -> None:
    engine = Engine()
    boot = M.Boot(M.PROTOCOL_VERSION, M.SCHEMA_HASH, M.ResetCause.POWER_ON, M.ConfigStatus.LOADED)
    engine.receive(frame(M.BOARD_SEQ_FLAG, boot), 0.0)
    with pytest.raises(BoardResetError):
        engine.start_request(M.Ping(1))
    engine.start_handshake(3.0, 0.0)
    send(engine, 0.0)
    send(engine, 0.0)
    engine.receive(frame(M.BOARD_SEQ_FLAG, boot), 0.01)  # it booted while we asked
    seq = seq_of(send(engine, 0.01))  # asked again at once
    engine.receive(frame(seq, identity()), 0.02)
    assert engine.poll(0.02) == Done(identity())
    assert engine.identity == identity()
    start(engine, M.Ping(1), 0.03)


def test_the_handshake_names_both_versions_and_hashes_on_mismatch() -> None:
    engine = Engine()
    engine.start_handshake(3.0, 0.0)
    send(engine, 0.0)
    seq = seq_of(send(engine, 0.0))
    other = identity(version=2, schema=0xDEADBEEF).encode() + b"\x01\x02"  # a longer identity
    engine.receive(encode_frame(seq, M.Identity.ID, other), 0.01)
    done = engine.poll(0.01)
    assert isinstance(done, Done) and isinstance(done.error, SchemaMismatchError)
    assert (done.error.board_version, done.error.board_hash) == (2, 0xDEADBEEF)
    assert engine.identity is None


def test_stream_frames_are_delivered_and_seq_gaps_count_as_lost() -> None:
    engine = Engine()
    seqs = [0x80, 0x81, 0x83, 0xFF, 0x81]  # one lost, 123 lost, one lost across the wrap
    data = b"".join(frame(s, state_sample(i)) for i, s in enumerate(seqs))
    items = engine.receive(data, 5.0)
    assert [t.seq for t in items] == seqs
    assert [t.message.board_time for t in items] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert all(t.received_s == 5.0 for t in items)
    stats = engine.stats()
    assert (stats.stream_frames, stats.stream_lost) == (5, 1 + 123 + 1)


def test_a_state_reply_goes_to_the_request_not_the_stream() -> None:
    engine = Engine()
    seq = start(engine, M.GetState(), 0.0)
    assert engine.receive(frame(seq, state_sample(9.0)), 0.01) == []
    done = engine.poll(0.01)
    assert M.State.decode(done.result().body) == state_sample(9.0)  # type: ignore[union-attr]
    assert engine.stats().stream_frames == 0


def test_damaged_frames_and_bodies_are_counted_not_delivered() -> None:
    engine = Engine()
    good = frame(0x80, state_sample())
    damaged = bytearray(good)
    damaged[5] ^= 0x01
    bad_body = encode_frame(0x81, M.State.ID, b"\x00" * 3)
    assert engine.receive(bytes(damaged) + bad_body, 0.0) == []
    stats = engine.stats()
    assert (stats.crc_errors, stats.decode_errors, stats.stream_frames) == (1, 1, 1)


def test_heartbeats_fall_due_when_the_board_was_not_heard_for_a_period() -> None:
    engine = Engine(heartbeat_period_s=0.1)
    assert engine.heartbeat_due() is None and engine.heartbeat(5.0) is None  # no handshake
    shake_hands(engine, 1.0)
    assert engine.heartbeat_due() == pytest.approx(1.1)
    assert engine.heartbeat(1.09) is None
    tx = engine.heartbeat(1.1)
    assert tx is not None and tx.kind is Kind.HEARTBEAT
    engine.sent(tx, 1.1)
    assert engine.heartbeat_due() == pytest.approx(1.2)
    ping_seq = start(engine, M.Ping(1), 1.15)  # a frame sent does not put it off: it may be lost
    assert engine.heartbeat_due() == pytest.approx(1.2)
    engine.receive(frame(seq_of(tx), M.Ack(M.Heartbeat.ID)), 1.16)  # its ack is absorbed...
    stats = engine.stats()
    assert (stats.heartbeats, stats.stale_replies) == (1, 0)
    assert engine.heartbeat_due() == pytest.approx(1.26)  # ...and says the board took it
    engine.receive(frame(ping_seq, M.Pong(1, 0.0)), 1.21)  # the request's reply
    assert engine.heartbeat_due() == pytest.approx(1.31)
    engine.heartbeat_period_s = None
    assert engine.heartbeat_due() is None


def test_the_next_heartbeats_frames_are_the_ones_the_engine_makes() -> None:
    """What the harness sending the heartbeats itself is given (simlink_stops): the next
    frames as Engine.heartbeat() makes them, across the seq's wrap."""
    from utrf.hand.simlink_stops import next_heartbeats

    engine = Engine(heartbeat_period_s=0.1)
    shake_hands(engine, 1.0)
    start(engine, M.Ping(1), 1.0)  # a request moves the seq: the frames follow it
    for _ in range(125):
        engine._next_seq()  # near the wrap (host seqs 0..127)
    ahead = next_heartbeats(engine, 4)
    assert [seq for seq, _ in ahead] == [127, 0, 1, 2]
    sent = []
    for i, (seq, data) in enumerate(ahead):
        tx = engine.heartbeat(1.1 + i)
        assert tx is not None and tx.data == data and seq_of(tx) == seq
        engine.sent(tx, 1.1 + i)
        sent.append(seq)
    assert engine._heartbeat_seqs == set(sent)  # what the harness is told is awaited


def test_a_lost_line_fails_the_request_and_every_next_one() -> None:
    engine = Engine()
    start(engine, M.Ping(1), 0.0)
    engine.fail(DisconnectedError("the line went away"))
    assert engine.settled
    done = engine.poll(0.01)
    assert isinstance(done, Done) and isinstance(done.error, DisconnectedError)
    engine.fail(DisconnectedError("the link was closed"))  # the first reason stays
    with pytest.raises(DisconnectedError, match="went away"):
        engine.start_request(M.Ping(2))
    with pytest.raises(DisconnectedError):
        engine.start_handshake(1.0, 0.0)


def test_bad_requests_raise_before_anything_is_sent_and_one_at_a_time() -> None:
    engine = Engine()
    with pytest.raises(TypeError, match="Pong is not a request"):
        engine.start_request(M.Pong(1, 0.0))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"set_telemetry\.rate_hz: 1001 is outside"):
        engine.start_request(M.SetTelemetry(rate_hz=1001))
    start(engine, M.Ping(1), 0.0)
    with pytest.raises(RuntimeError, match="one at a time"):
        engine.start_request(M.Ping(2))
    engine.abandon()  # its driver gave up: a late reply is stale
    engine.receive(frame(0, M.Pong(1, 0.0)), 0.01)
    assert engine.stats().stale_replies == 1
    with pytest.raises(ValueError, match="retries must be >= 0"):
        Engine(retries=-1)
    with pytest.raises(ValueError, match="heartbeat_period_s must be positive"):
        Engine(heartbeat_period_s=0.0)


# --- resends and what a timeout says --------------------------------------------------------


def test_a_timeout_after_silence_says_the_outcome_is_unknown() -> None:
    engine = Engine(retries=1)
    start(engine, TARGETS, 0.0)
    send(engine, T)
    done = engine.poll(2 * T)
    assert isinstance(done, Done) and isinstance(done.error, ReplyTimeout)
    assert done.error.outcome is Outcome.UNKNOWN
    assert "(unknown)" in str(done.error)


def test_attempts_refused_damaged_are_known_not_applied() -> None:
    # Each attempt came back as BAD_CRC naming it: none was applied. With its last attempt
    # the request ends as a NackError; a timeout before that hint counts what is known.
    engine = Engine(retries=1)
    seq = start(engine, TARGETS, 0.0)
    engine.receive(frame(seq, bad_crc(TARGETS.ID)), 0.01)
    assert send(engine, 0.01).data == frame(seq, TARGETS)  # resent at once, same bytes
    assert send(engine, 0.01 + T).data == frame(seq, TARGETS)  # the timeout's resend
    done = engine.poll(0.01 + 2 * T)
    assert isinstance(done.error, ReplyTimeout)  # type: ignore[union-attr]
    assert done.error.outcome is Outcome.UNKNOWN  # type: ignore[union-attr]  # silence after
    engine = Engine(retries=0)
    seq = start(engine, TARGETS, 0.0)
    pending = engine._pending
    assert pending is not None and pending.maybe_applied == 1
    engine.receive(frame(seq, bad_crc(TARGETS.ID)), 0.01)
    assert pending.maybe_applied == 0
    done = engine.poll(0.01)
    assert isinstance(done.error, NackError) and done.error.code is M.ErrorCode.BAD_CRC  # type: ignore[union-attr]
    # a hint naming another frame says nothing about ours
    engine = Engine(retries=0)
    seq = start(engine, TARGETS, 0.0)
    engine.receive(frame(seq, bad_crc(M.SetMode.ID)), 0.01)
    assert engine._pending is not None and engine._pending.maybe_applied == 1
    done = engine.poll(T)
    assert done.error.outcome is Outcome.UNKNOWN  # type: ignore[union-attr]


def test_a_timeout_with_no_attempt_written_is_known_not_applied() -> None:
    engine = Engine(retries=0)
    engine.start_request(TARGETS)
    action = engine.poll(0.0)
    assert isinstance(action, Transmit)  # never reported written: the driver was stopped
    pending = engine._pending
    assert pending is not None
    pending.deadline = 0.0  # as if its time had run out
    done = engine.poll(1.0)
    assert isinstance(done.error, ReplyTimeout)  # type: ignore[union-attr]
    assert done.error.outcome is Outcome.NOT_APPLIED  # type: ignore[union-attr]
