"""The protocol's client rules, without I/O: :class:`Engine`.

Everything ``protocol/README.md`` asks of a client lives here once: seq allocation, matching
replies to the request in flight, resends of idempotent requests after the reply timeout, the
``BAD_CRC`` nack as a hint, ``nack`` → :class:`NackError`, ``boot`` → :class:`BoardResetError`
until the next handshake, the handshake's version and hash check and its retry loop, stream
delivery and loss counted from seq gaps, heartbeats when idle, and the statistics.

The engine has no threads, no clock and no line of its own. Its driver feeds it what the
board sent and the current time, and does what it asks: write a :class:`Transmit` (then
report it with :meth:`Engine.sent`), or wait until a :class:`Wait`'s time or until the
request is :attr:`~Engine.settled`, whichever comes first, and poll again. A request ends
with a :class:`Done`. :class:`~utrf.protocol.link.Link` drives it from threads on the wall
clock; :class:`~utrf.hand.simlink.SimLink` steps an emulated board in simulated time.

    engine = Engine()
    engine.start_request(Ping(1))
    action = engine.poll(now)            # Transmit(frame): write it, then engine.sent(action, t)
    items = engine.receive(data, now)    # the board's stream, fault and boot messages
    action = engine.poll(now)            # Wait(until) or Done(value or error)
    engine.heartbeat(now)                # a heartbeat's Transmit when one is due, else None
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Any, Self, cast

from utrf.protocol import messages as m
from utrf.protocol.codec import Request
from utrf.protocol.errors import (
    BoardResetError,
    DecodeError,
    DisconnectedError,
    NackError,
    Outcome,
    ProtocolError,
    ReplyTimeout,
    SchemaMismatchError,
)
from utrf.protocol.framing import DELIMITER, Frame, FrameDecoder, FrameError, RxEvent, encode_frame

log = logging.getLogger(__name__)

StreamMessage = m.State | m.Status | m.Fault | m.Boot
#: board-initiated messages: one running seq counts them all (a gap is a loss of any of them)
STREAM_IDS = frozenset({m.State.ID, m.Status.ID, m.Fault.ID, m.Boot.ID})
SEQ_MASK = m.BOARD_SEQ_FLAG - 1  # host seqs run 0..127, the board's stream counter likewise
#: heartbeat seqs remembered so that their acks are not counted as stale
HEARTBEAT_SEQS_KEPT = 32


@dataclass(frozen=True, slots=True)
class Telemetry:
    """A board-initiated message as delivered to the queue and the callbacks."""

    message: StreamMessage
    seq: int
    received_s: float  # the driver's clock when its last byte arrived


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counters since the link was opened (a snapshot; see :meth:`Engine.stats`)."""

    tx_frames: int = 0
    rx_frames: int = 0
    crc_errors: int = 0
    framing_errors: int = 0
    oversize: int = 0
    decode_errors: int = 0  # frames whose body is not a valid message: dropped
    stale_replies: int = 0  # replies nobody waits for any more (late, or duplicates)
    retries: int = 0
    timeouts: int = 0
    nacks: int = 0
    heartbeats: int = 0
    stream_frames: int = 0
    stream_lost: int = 0  # gaps in the board's stream seqs
    telemetry_dropped: int = 0  # the queue was full: the oldest items were dropped


_STAT_NAMES = tuple(f.name for f in fields(LinkStats))
_ERROR_STATS = {
    RxEvent.CRC_ERROR: "crc_errors",
    RxEvent.FRAMING_ERROR: "framing_errors",
    RxEvent.OVERSIZE: "oversize",
}


class Kind(Enum):
    """What a :class:`Transmit` carries."""

    REQUEST = "request"  # a request's frame (first attempt or a resend)
    HEARTBEAT = "heartbeat"
    DELIMITER = "delimiter"  # a lone 0x00 before the handshake


@dataclass(frozen=True, slots=True)
class Transmit:
    """Write ``data`` to the board, then report it with :meth:`Engine.sent`."""

    data: bytes
    kind: Kind


@dataclass(frozen=True, slots=True)
class Wait:
    """Nothing to do until ``until`` (the driver's clock) or until the engine is settled."""

    until: float


@dataclass(frozen=True, slots=True)
class Done:
    """The request (a reply :class:`Frame`) or the handshake (an ``Identity``) ended."""

    value: Any = None
    error: BaseException | None = None

    def result(self) -> Any:
        if self.error is not None:
            raise self.error
        return self.value


Action = Transmit | Wait | Done


@dataclass(frozen=True, slots=True)
class _Hint:
    """A BAD_CRC nack while an idempotent request waits: resend now if a hint's resend is
    left, else end with ``error`` (None: keep waiting)."""

    error: NackError | None


@dataclass(slots=True)
class _Pending:
    """The request in flight, one attempt after another."""

    request: Request[Any]
    seq: int
    frame: bytes
    timeout_s: float
    allowed: int  # attempts on timeouts: the first and the resends after a timeout
    attempt: int = 0  # attempts sent, on timeouts and on hints
    #: resends at once on a BAD_CRC hint: they take a millisecond, not a timeout, so they have
    #: their own budget (as many as the retries) and leave the timeouts' resends whole
    hinted: int = 0
    #: attempts written out that no BAD_CRC nack naming this request accounts for: each
    #: may have been applied (its reply lost)
    maybe_applied: int = 0
    deadline: float | None = None  # None: (re)send now; inf: sent, not yet reported
    inbox: deque[Frame | _Hint | BaseException] = field(default_factory=deque)


@dataclass(slots=True)
class _Handshake:
    deadline: float
    attempts: int = 0
    delimiter_sent: bool = False


class Engine:
    """The client's protocol state: one request or handshake at a time, the board's stream,
    heartbeats and statistics. Not thread-safe: a threaded driver holds its own lock around
    every call.

    ``retries``: resends of an idempotent request after a timeout; as many again at once on
    BAD_CRC nacks naming it (the board saw a damaged frame: a millisecond, not a timeout).
    ``heartbeat_period_s``: after a successful handshake, a heartbeat falls due when for this
    long the board has not been heard to take a frame (a reply to a request or a heartbeat)
    and no heartbeat went out (None: never); a request being resent does not put it off.
    ``now``: the driver's clock at the start.
    """

    def __init__(
        self,
        *,
        retries: int = m.RETRIES,
        heartbeat_period_s: float | None = m.HEARTBEAT_PERIOD_S,
        now: float = 0.0,
    ) -> None:
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if heartbeat_period_s is not None and heartbeat_period_s <= 0:
            raise ValueError(
                f"heartbeat_period_s must be positive or None, got {heartbeat_period_s}"
            )
        self.retries = retries
        self.heartbeat_period_s = heartbeat_period_s
        self._counts = dict.fromkeys(_STAT_NAMES, 0)
        self._decoder = FrameDecoder()
        self._seq = 0
        self._pending: _Pending | None = None
        self._handshake: _Handshake | None = None
        self._heartbeat_seqs: set[int] = set()
        self._last_stream_seq: int | None = None
        self._last_heard = now  # the board's last reply to a frame of ours: it took that frame
        self._last_heartbeat = now
        self._identity: m.Identity | None = None
        self._reset: BoardResetError | None = None
        self._closed: DisconnectedError | None = None

    # --- state -----------------------------------------------------------------------------

    @property
    def identity(self) -> m.Identity | None:
        """The board's identity from the last successful handshake (None after a boot)."""
        return self._identity

    @property
    def closed(self) -> DisconnectedError | None:
        return self._closed

    @property
    def settled(self) -> bool:
        """Something arrived for the request in flight: poll now rather than at its time."""
        return self._pending is not None and bool(self._pending.inbox)

    def stats(self) -> LinkStats:
        return LinkStats(**self._counts)

    def count(self, name: str, n: int = 1) -> None:
        """Add to a counter of :class:`LinkStats` (a driver's own, e.g. telemetry_dropped)."""
        self._counts[name] += n

    def check_usable(self) -> None:
        """Raise why no request can be made: the line is closed, or the board reset."""
        if self._closed is not None:
            raise self._closed
        if self._reset is not None:
            raise self._reset

    # --- starting a request or the handshake ------------------------------------------------

    def start_request(
        self, msg: Request[Any], *, timeout_s: float | None = None, retries: int | None = None
    ) -> None:
        """Make ``msg`` the request in flight; :meth:`poll` drives it.

        Raises TypeError for a message that is no request, ValueError (nothing sent) for one
        that cannot be encoded, and what :meth:`check_usable` raises.
        """
        if not isinstance(msg, Request):
            raise TypeError(f"{type(msg).__name__} is not a request (host_to_board) message")
        body = msg.encode()
        self.check_usable()
        self._begin()
        timeout = msg.REPLY_TIMEOUT_S if timeout_s is None else timeout_s
        self._pending = self._new_pending(msg, body, timeout, retries)

    def start_handshake(self, timeout_s: float, now: float) -> None:
        """Start the handshake: a lone 0x00, then ``identify`` until a reply comes or
        ``timeout_s`` passes. Clears a pending BoardResetError (the way back after a boot)."""
        if self._closed is not None:
            raise self._closed
        self._begin()
        self._reset = None
        self._handshake = _Handshake(deadline=now + timeout_s)

    def _begin(self) -> None:
        if self._pending is not None or self._handshake is not None:
            raise RuntimeError("a request is already in flight: one at a time")

    def _new_pending(
        self, msg: Request[Any], body: bytes, timeout_s: float, retries: int | None
    ) -> _Pending:
        allowed = 1 + ((self.retries if retries is None else retries) if msg.IDEMPOTENT else 0)
        seq = self._next_seq()
        return _Pending(msg, seq, encode_frame(seq, msg.ID, body), timeout_s, allowed)

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) & SEQ_MASK
        return seq

    def abandon(self) -> None:
        """Forget the request or handshake in flight (its driver gave up, e.g. a write
        failed); a late reply to it then counts as stale."""
        self._pending = None
        self._handshake = None

    # --- driving it ---------------------------------------------------------------------------

    def poll(self, now: float) -> Action:
        """What the request or handshake in flight needs at ``now``."""
        if self._handshake is not None:
            return self._poll_handshake(self._handshake, now)
        if self._pending is None:
            raise RuntimeError("no request in flight")
        return self._poll_pending(self._pending, now)

    def sent(self, tx: Transmit, now: float) -> None:
        """``tx`` went out at ``now``: the reply timeout runs from here."""
        if tx.kind is Kind.REQUEST:
            self._counts["tx_frames"] += 1
            pending = self._pending
            if pending is not None and pending.deadline == math.inf:
                pending.deadline = now + pending.timeout_s
                pending.maybe_applied += 1
        elif tx.kind is Kind.HEARTBEAT:
            self._last_heartbeat = now
            self._counts["tx_frames"] += 1
            self._counts["heartbeats"] += 1

    def _poll_pending(self, p: _Pending, now: float) -> Action:
        inbox = p.inbox
        while inbox:
            outcome = inbox.popleft()
            if isinstance(outcome, Frame):
                return self._done(value=outcome)
            if isinstance(outcome, _Hint):
                if p.hinted < p.allowed - 1:
                    p.hinted += 1
                    return self._transmit(p)  # resend now rather than at the timeout
                if outcome.error is not None:
                    return self._done(error=outcome.error)
                continue
            return self._done(error=outcome)
        if p.deadline is None:
            return self._transmit(p)
        if now < p.deadline:
            return Wait(p.deadline)
        if p.attempt - p.hinted < p.allowed:
            return self._transmit(p)
        self._counts["timeouts"] += 1
        applied = Outcome.UNKNOWN if p.maybe_applied else Outcome.NOT_APPLIED
        return self._done(error=ReplyTimeout(p.request, p.timeout_s, p.attempt, applied))

    def _transmit(self, p: _Pending) -> Transmit:
        p.attempt += 1
        if p.attempt > 1:
            self._counts["retries"] += 1
        p.deadline = math.inf  # until sent() starts the timeout
        return Transmit(p.frame, Kind.REQUEST)

    def _done(self, value: Any = None, error: BaseException | None = None) -> Done:
        self._pending = None
        return Done(value, error)

    def _poll_handshake(self, hs: _Handshake, now: float) -> Action:
        if not hs.delimiter_sent:
            hs.delimiter_sent = True
            return Transmit(DELIMITER, Kind.DELIMITER)  # end whatever partial frame it holds
        while True:
            if self._pending is None:
                remaining = hs.deadline - now
                if remaining <= 0:
                    self._handshake = None
                    return Done(
                        error=ReplyTimeout(m.Identify(), m.Identify.REPLY_TIMEOUT_S, hs.attempts)
                    )
                hs.attempts += 1
                timeout = min(m.Identify.REPLY_TIMEOUT_S, remaining)
                self._pending = self._new_pending(m.Identify(), b"", timeout, 0)
            action = self._poll_pending(self._pending, now)
            if not isinstance(action, Done):
                return action
            if isinstance(action.error, ReplyTimeout):
                continue  # a board in its bootloader: ask again
            if isinstance(action.error, BoardResetError):
                self._reset = None  # it booted while we asked: ask again
                continue
            self._handshake = None
            if action.error is not None:
                return action
            try:
                identity = _check_identity(action.value.body)
            except ProtocolError as exc:
                return Done(error=exc)
            self._identity = identity
            self._last_heard = now
            return Done(identity)

    # --- heartbeats ---------------------------------------------------------------------------

    def heartbeat_due(self) -> float | None:
        """When the next heartbeat falls due, on the driver's clock; None while heartbeats
        are off (no period, no handshake yet, the board reset, the line closed)."""
        if (
            self.heartbeat_period_s is None
            or self._identity is None
            or self._reset is not None
            or self._closed is not None
        ):
            return None
        # Counted from what the board is known to have taken, not from what went out: a long
        # request resent on a noisy line may all be lost, and the board's watchdog with it.
        return max(self._last_heard, self._last_heartbeat) + self.heartbeat_period_s

    def heartbeat(self, now: float) -> Transmit | None:
        """A heartbeat to write if one is due at ``now``; its ack will not count as stale."""
        due = self.heartbeat_due()
        if due is None or due > now:
            return None
        seq = self._next_seq()
        self._heartbeat_seqs.add(seq)
        if len(self._heartbeat_seqs) > HEARTBEAT_SEQS_KEPT:
            self._heartbeat_seqs.pop()
        return Transmit(encode_frame(seq, m.Heartbeat.ID), Kind.HEARTBEAT)

    # --- what the board sends -------------------------------------------------------------------

    def fail(self, error: DisconnectedError) -> None:
        """The line went away or was closed: the request in flight and every later one fail."""
        if self._closed is None:
            self._closed = error
        if self._pending is not None:
            self._pending.inbox.append(error)

    def frames(self, data: bytes) -> list[Frame | FrameError]:
        """Decode received bytes; hand each event to :meth:`handle`, in order."""
        return self._decoder.feed(data)

    def receive(self, data: bytes, now: float) -> list[Telemetry]:
        """Decode and handle received bytes; returns the board's messages to deliver."""
        items = []
        for event in self._decoder.feed(data):
            item = self.handle(event, now)
            if item is not None:
                items.append(item)
        return items

    def handle(self, event: Frame | FrameError, now: float) -> Telemetry | None:
        """One received frame or error; returns a stream, fault or boot message to deliver."""
        try:
            if isinstance(event, FrameError):
                self._counts[_ERROR_STATS[event.kind]] += 1
                return None
            return self._on_frame(event, now)
        except Exception:  # never let one frame stop the receiver
            log.exception("utrf link: error handling %r", event)
            return None

    def _on_frame(self, frame: Frame, now: float) -> Telemetry | None:
        counts = self._counts
        counts["rx_frames"] += 1
        msg_id = frame.msg_id
        if msg_id == m.Boot.ID:
            return self._on_boot(frame, now)
        if msg_id in STREAM_IDS and frame.seq & m.BOARD_SEQ_FLAG:
            return self._on_stream(frame, now)
        if msg_id == m.Nack.ID:
            self._on_nack(frame, now)
            return None
        pending = self._pending
        if pending is not None and frame.seq == pending.seq:
            self._last_heard = now
            request = pending.request
            reply_cls = type(request).REPLY
            if msg_id == reply_cls.ID:
                if msg_id == m.Ack.ID and frame.body != bytes([request.ID]):
                    counts["stale_replies"] += 1  # an ack of something else
                    return None
                pending.inbox.append(frame)
                return None
            name = m.BY_ID[msg_id].NAME if msg_id in m.BY_ID else hex(msg_id)
            pending.inbox.append(
                ProtocolError(f"{request.NAME} was answered with {name}, expected {reply_cls.NAME}")
            )
            return None
        if msg_id == m.Ack.ID and frame.seq in self._heartbeat_seqs:
            self._heartbeat_seqs.discard(frame.seq)
            self._last_heard = now
            return None
        counts["stale_replies"] += 1
        return None

    def _on_nack(self, frame: Frame, now: float) -> None:
        try:
            nack = m.Nack.decode(frame.body)
        except DecodeError:
            self._counts["decode_errors"] += 1
            return
        self._counts["nacks"] += 1
        pending = self._pending
        if pending is None:
            return
        request = pending.request
        matches = frame.seq == pending.seq and nack.msg_id == request.ID
        if matches and nack.code is not m.ErrorCode.BAD_CRC:
            self._last_heard = now
        error = NackError(nack.code, nack.detail, request)
        if nack.code is m.ErrorCode.BAD_CRC:
            # The board saw a damaged frame, maybe ours. A hint: resend an idempotent request
            # now rather than at its timeout. It ends the request only if it names this very
            # request (seq and id) and no attempt is left. Naming it, it also says that one
            # attempt arrived damaged: that one was not applied.
            if matches and pending.maybe_applied:
                pending.maybe_applied -= 1
            if request.IDEMPOTENT:
                pending.inbox.append(_Hint(error if matches else None))
                return
            if not matches:
                return
        if not matches:
            self._counts["stale_replies"] += 1
            return
        pending.inbox.append(error)

    def _on_stream(self, frame: Frame, now: float) -> Telemetry | None:
        last = self._last_stream_seq
        self._last_stream_seq = frame.seq
        self._counts["stream_frames"] += 1
        if last is not None:
            self._counts["stream_lost"] += (frame.seq - last - 1) & SEQ_MASK
        cls = m.BY_ID[frame.msg_id]
        try:
            message = cls.decode(frame.body)
        except DecodeError as exc:
            log.warning("utrf link: dropped a %s frame: %s", cls.NAME, exc)
            self._counts["decode_errors"] += 1
            return None
        # only the stream's ids reach here (the dispatch on msg_id): the cast says so
        return Telemetry(cast(StreamMessage, message), frame.seq, now)

    def _on_boot(self, frame: Frame, now: float) -> Telemetry | None:
        self._last_stream_seq = frame.seq
        boot: m.Boot | None
        try:
            boot = m.Boot.decode(frame.body)
        except DecodeError as exc:
            log.warning("utrf link: the board reset; its boot message does not decode: %s", exc)
            boot = None
        error = BoardResetError(boot)
        self._reset = error
        self._identity = None
        if self._pending is not None:
            self._pending.inbox.append(error)
        return None if boot is None else Telemetry(boot, frame.seq, now)


class EngineDriver:
    """What :class:`~utrf.protocol.link.Link` and :class:`~utrf.hand.simlink.SimLink` show of
    their engine alike: the identity, the settings, and closing as a context manager."""

    _engine: Engine

    @property
    def identity(self) -> m.Identity | None:
        """The board's identity from the last successful handshake."""
        return self._engine.identity

    @property
    def retries(self) -> int:
        """Resends of an idempotent request after the first attempt."""
        return self._engine.retries

    @retries.setter
    def retries(self, value: int) -> None:
        self._engine.retries = value

    @property
    def heartbeat_period_s(self) -> float | None:
        """Longest silence before a heartbeat, once handshaken (None: no heartbeats)."""
        return self._engine.heartbeat_period_s

    @heartbeat_period_s.setter
    def heartbeat_period_s(self, value: float | None) -> None:
        self._engine.heartbeat_period_s = value

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def call_each(callbacks: Iterable[Callable[[Telemetry], None]], item: Telemetry) -> None:
    """Hand ``item`` to every callback; one that fails is logged and does not stop the rest."""
    for callback in callbacks:
        try:
            callback(item)
        except Exception:
            log.exception("utrf link: telemetry callback %r failed", callback)


def _check_identity(body: bytes) -> m.Identity:
    """The handshake's check: protocol_version (u16) and schema_hash (u32), the fixed head of
    ``identity`` in every version, before anything else is decoded."""
    if len(body) < 6:
        why = f"body of {len(body)} bytes is too short for its version"
        raise DecodeError("identity", None, why)
    version = int.from_bytes(body[0:2], "little")
    schema = int.from_bytes(body[2:6], "little")
    if (version, schema) != (m.PROTOCOL_VERSION, m.SCHEMA_HASH):
        raise SchemaMismatchError(m.PROTOCOL_VERSION, m.SCHEMA_HASH, version, schema)
    return m.Identity.decode(body)
