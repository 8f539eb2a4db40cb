"""Requests and replies over a line to the board: :class:`Link`.

One request is in flight at a time; its reply echoes its seq. A request that gets no reply
within its ``REPLY_TIMEOUT_S`` is resent (same seq, same bytes) when it is idempotent, up to
``retries`` times, and raises :class:`ReplyTimeout` after that; a request that is not
idempotent is never resent. The board's own frames (``state`` stream, ``fault``, ``boot``)
carry seqs with ``BOARD_SEQ_FLAG`` set from a running counter; they go to :attr:`Link.telemetry`
(a queue) and to callbacks, from the reader thread, so they never wait for a request and a
request never waits for them. A gap in their seqs counts as lost frames.

    with Link.open("socket://127.0.0.1:5555") as link:
        identity = link.handshake()          # SchemaMismatchError if the firmware differs
        link.request(SetTelemetry(rate_hz=100))
        item = link.telemetry.get(timeout=1.0)  # Telemetry(message=State(...), ...)

Thread-safe: any thread may call :meth:`Link.request`; calls are served one at a time.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TypeVar

from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.errors import (
    BoardResetError,
    DecodeError,
    DisconnectedError,
    NackError,
    ProtocolError,
    ReplyTimeout,
    SchemaMismatchError,
)
from utrf.protocol.framing import Frame, FrameDecoder, FrameError, RxEvent, encode_frame
from utrf.protocol.transport import SerialTransport, Transport

log = logging.getLogger(__name__)

R = TypeVar("R", bound=Message)
StreamMessage = m.State | m.Fault | m.Boot
_STREAM_IDS = {m.State.ID, m.Fault.ID, m.Boot.ID}
_SEQ_MASK = m.BOARD_SEQ_FLAG - 1  # host seqs run 0..127, the board's stream counter likewise


@dataclass(frozen=True, slots=True)
class Telemetry:
    """A board-initiated message as delivered to the queue and the callbacks."""

    message: StreamMessage
    seq: int
    received_s: float  # time.monotonic() when its last byte arrived


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counters since the link was opened (a snapshot; see :meth:`Link.stats`)."""

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


class _Outcome:
    """What the reader thread tells the waiting request."""

    __slots__ = ("error", "error_if_final", "frame", "resend")

    def __init__(
        self,
        frame: Frame | None = None,
        error: BaseException | None = None,
        resend: bool = False,
        error_if_final: BaseException | None = None,
    ) -> None:
        self.frame = frame
        self.error = error
        self.resend = resend  # resend now if an attempt is left
        self.error_if_final = error_if_final  # ...else raise this (None: keep waiting)


@dataclass
class _Pending:
    seq: int
    request: Request[Message]
    inbox: queue.SimpleQueue[_Outcome]


class Link:
    """Request/response and telemetry over a :class:`Transport`.

    ``heartbeat_period_s``: after a successful :meth:`handshake`, send a ``heartbeat`` when
    nothing else went out for this long (None: never), so the board's host-silence watchdog
    stays fed. ``retries``: resends of an idempotent request after the first attempt.
    ``telemetry_queue_size``: when :attr:`telemetry` is full the oldest items are dropped.
    Callbacks (``on_telemetry``) run on the reader thread: keep them short.
    """

    def __init__(
        self,
        transport: Transport,
        *,
        retries: int = m.RETRIES,
        heartbeat_period_s: float | None = m.HEARTBEAT_PERIOD_S,
        telemetry_queue_size: int = 1024,
        on_telemetry: Callable[[Telemetry], None] | None = None,
    ) -> None:
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if heartbeat_period_s is not None and heartbeat_period_s <= 0:
            raise ValueError(
                f"heartbeat_period_s must be positive or None, got {heartbeat_period_s}"
            )
        self.retries = retries
        self.heartbeat_period_s = heartbeat_period_s
        self.telemetry: queue.Queue[Telemetry] = queue.Queue(maxsize=telemetry_queue_size)
        self._callbacks: list[Callable[[Telemetry], None]] = []
        if on_telemetry is not None:
            self._callbacks.append(on_telemetry)
        self._transport = transport
        self._decoder = FrameDecoder()
        self._lock = threading.Lock()  # guards the state below
        self._request_lock = threading.Lock()  # one request in flight
        self._stats = LinkStats()
        self._seq = 0
        self._pending: _Pending | None = None
        self._heartbeat_seqs: set[int] = set()
        self._last_stream_seq: int | None = None
        self._last_tx = time.monotonic()
        self._closed: DisconnectedError | None = None
        self._reset: BoardResetError | None = None
        self._identity: m.Identity | None = None
        self._stop = threading.Event()
        self._heartbeat_thread: threading.Thread | None = None
        transport.start(self._on_data, self._on_close)
        if heartbeat_period_s is not None:
            self._heartbeat_thread = threading.Thread(
                target=self._heartbeat_loop, name="utrf-heartbeat", daemon=True
            )
            self._heartbeat_thread.start()

    @classmethod
    def open(cls, url: str, baudrate: int = m.DEFAULT_BAUD, **kwargs: object) -> Link:
        """A link over ``serial.serial_for_url(url)``; keyword arguments go to :class:`Link`."""
        return cls(SerialTransport(url, baudrate), **kwargs)  # type: ignore[arg-type]

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the line; a waiting request raises DisconnectedError."""
        self._stop.set()
        self._fail(DisconnectedError("the link was closed"))
        self._transport.close()
        if (
            self._heartbeat_thread is not None
            and self._heartbeat_thread is not threading.current_thread()
        ):
            self._heartbeat_thread.join(timeout=1.0)

    # --- public API ----------------------------------------------------------------------

    @property
    def identity(self) -> m.Identity | None:
        """The board's identity from the last successful handshake."""
        return self._identity

    def stats(self) -> LinkStats:
        with self._lock:
            return self._stats

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        with self._lock:
            self._callbacks.append(callback)

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        with self._lock:
            self._callbacks.remove(callback)

    def request(
        self, msg: Request[R], *, timeout_s: float | None = None, retries: int | None = None
    ) -> R:
        """Send ``msg`` and return its reply (an ``Ack`` when the spec names none).

        Raises ValueError (nothing sent) for a message that cannot be encoded,
        :class:`NackError` when the board refuses, :class:`ReplyTimeout`,
        :class:`DecodeError` for a reply that is not a valid message,
        :class:`BoardResetError` after the board reset, :class:`DisconnectedError`.
        """
        if not isinstance(msg, Request):
            raise TypeError(f"{type(msg).__name__} is not a request (host_to_board) message")
        body = msg.encode()
        with self._request_lock:
            self._check_usable()
            frame = self._exchange(msg, body, timeout_s, retries)
        reply_cls = type(msg).REPLY
        reply = reply_cls.decode(frame.body)
        return reply  # type: ignore[return-value]

    def handshake(self, timeout_s: float = 3.0) -> m.Identity:
        """Ask the board who it is, and check that it speaks this host's protocol.

        Sends ``identify`` until a reply comes or ``timeout_s`` passes (a board that just
        reset may still be in its bootloader). Clears a pending :class:`BoardResetError`:
        this is how the host reconnects after a reset. Raises :class:`SchemaMismatchError`
        naming both protocol versions and schema hashes when the firmware was built from
        another spec; the first two fields of ``identity`` keep their place in every version.
        """
        deadline = time.monotonic() + timeout_s
        with self._request_lock:
            with self._lock:
                if self._closed is not None:
                    raise self._closed
                self._reset = None
            self._write(b"\x00")  # end whatever partial frame the board holds
            attempts = 0
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise ReplyTimeout(m.Identify(), m.Identify.REPLY_TIMEOUT_S, attempts)
                attempts += 1
                try:
                    frame = self._exchange(
                        m.Identify(), b"", min(m.Identify.REPLY_TIMEOUT_S, remaining), 0
                    )
                except ReplyTimeout:
                    continue
                except BoardResetError:
                    with self._lock:
                        self._reset = None  # it booted while we asked: ask again
                    continue
                break
        version, schema = _version_and_hash(frame.body, "identity")
        if (version, schema) != (m.PROTOCOL_VERSION, m.SCHEMA_HASH):
            raise SchemaMismatchError(m.PROTOCOL_VERSION, m.SCHEMA_HASH, version, schema)
        identity = m.Identity.decode(frame.body)
        with self._lock:
            self._identity = identity
        return identity

    # --- requests ------------------------------------------------------------------------

    def _check_usable(self) -> None:
        with self._lock:
            if self._closed is not None:
                raise self._closed
            if self._reset is not None:
                raise self._reset

    def _next_seq(self) -> int:
        with self._lock:
            seq = self._seq
            self._seq = (self._seq + 1) & _SEQ_MASK
            return seq

    def _write(self, data: bytes) -> None:
        try:
            self._transport.write(data)
        except DisconnectedError as exc:
            self._fail(exc)
            raise
        with self._lock:
            self._last_tx = time.monotonic()

    def _exchange(
        self, msg: Request[Message], body: bytes, timeout_s: float | None, retries: int | None
    ) -> Frame:
        """Send until the matching reply frame comes; nacks and failures raise."""
        timeout = msg.REPLY_TIMEOUT_S if timeout_s is None else timeout_s
        allowed = 1 + ((self.retries if retries is None else retries) if msg.IDEMPOTENT else 0)
        seq = self._next_seq()
        frame = encode_frame(seq, msg.ID, body)
        pending = _Pending(seq, msg, queue.SimpleQueue())
        with self._lock:
            self._pending = pending
        try:
            attempt = 0
            while True:
                attempt += 1
                if attempt > 1:
                    self._count(retries=1)
                self._write(frame)
                self._count(tx_frames=1)
                deadline = time.monotonic() + timeout
                while True:
                    remaining = deadline - time.monotonic()
                    try:
                        outcome = pending.inbox.get(timeout=max(remaining, 0.0))
                    except queue.Empty:
                        outcome = None
                    if outcome is None:
                        if attempt < allowed:
                            break  # resend
                        self._count(timeouts=1)
                        raise ReplyTimeout(msg, timeout, attempt)
                    if outcome.error is not None:
                        raise outcome.error
                    if outcome.resend:
                        if attempt < allowed:
                            break  # a BAD_CRC hint: resend now rather than at the timeout
                        if outcome.error_if_final is not None:
                            raise outcome.error_if_final
                        continue
                    assert outcome.frame is not None
                    return outcome.frame
        finally:
            with self._lock:
                self._pending = None

    # --- heartbeat -----------------------------------------------------------------------

    def _heartbeat_loop(self) -> None:
        assert self.heartbeat_period_s is not None
        period = self.heartbeat_period_s
        while not self._stop.is_set():
            with self._lock:
                due = self._last_tx + period
                ready = self._identity is not None and self._closed is None and self._reset is None
            wait = due - time.monotonic()
            if wait > 0:
                self._stop.wait(min(wait, period))
                continue
            if not ready:
                self._stop.wait(period)
                continue
            seq = self._next_seq()
            with self._lock:
                self._heartbeat_seqs.add(seq)
                if len(self._heartbeat_seqs) > 32:
                    self._heartbeat_seqs.pop()
            try:
                self._write(encode_frame(seq, m.Heartbeat.ID))
            except DisconnectedError:
                return
            self._count(tx_frames=1, heartbeats=1)

    # --- receiving (reader thread) -------------------------------------------------------

    def _count(self, **deltas: int) -> None:
        with self._lock:
            self._stats = replace(
                self._stats, **{k: getattr(self._stats, k) + v for k, v in deltas.items()}
            )

    def _on_close(self, error: BaseException | None) -> None:
        reason = f"the line went away: {error}" if error else "the line was closed"
        self._fail(DisconnectedError(reason))

    def _fail(self, error: DisconnectedError) -> None:
        with self._lock:
            if self._closed is None:
                self._closed = error
            pending = self._pending
        if pending is not None:
            pending.inbox.put(_Outcome(error=error))

    def _on_data(self, data: bytes) -> None:
        now = time.monotonic()
        for event in self._decoder.feed(data):
            try:
                if isinstance(event, FrameError):
                    self._on_frame_error(event)
                else:
                    self._on_frame(event, now)
            except Exception:  # never let one frame kill the reader
                log.exception("utrf link: error handling %r", event)

    def _on_frame_error(self, event: FrameError) -> None:
        field = {
            RxEvent.CRC_ERROR: "crc_errors",
            RxEvent.FRAMING_ERROR: "framing_errors",
            RxEvent.OVERSIZE: "oversize",
        }[event.kind]
        self._count(**{field: 1})

    def _on_frame(self, frame: Frame, now: float) -> None:
        self._count(rx_frames=1)
        with self._lock:
            pending = self._pending
        if frame.msg_id == m.Boot.ID:
            self._on_boot(frame, now)
            return
        if frame.msg_id in _STREAM_IDS and frame.seq & m.BOARD_SEQ_FLAG:
            self._on_stream(frame, now)
            return
        if frame.msg_id == m.Nack.ID:
            self._on_nack(frame, pending)
            return
        if pending is not None and frame.seq == pending.seq:
            request = pending.request
            if frame.msg_id == type(request).REPLY.ID:
                if frame.msg_id == m.Ack.ID and frame.body != bytes([request.ID]):
                    self._count(stale_replies=1)  # an ack of something else
                    return
                pending.inbox.put(_Outcome(frame=frame))
                return
            name = m.BY_ID[frame.msg_id].NAME if frame.msg_id in m.BY_ID else hex(frame.msg_id)
            pending.inbox.put(
                _Outcome(
                    error=ProtocolError(
                        f"{request.NAME} was answered with {name}, "
                        f"expected {type(request).REPLY.NAME}"
                    )
                )
            )
            return
        if frame.msg_id == m.Ack.ID:
            with self._lock:
                if frame.seq in self._heartbeat_seqs:
                    self._heartbeat_seqs.discard(frame.seq)
                    return
        self._count(stale_replies=1)

    def _on_nack(self, frame: Frame, pending: _Pending | None) -> None:
        try:
            nack = m.Nack.decode(frame.body)
        except DecodeError:
            self._count(decode_errors=1)
            return
        self._count(nacks=1)
        if pending is None:
            return
        request = pending.request
        matches = frame.seq == pending.seq and nack.msg_id == request.ID
        error = NackError(nack.code, nack.detail, request)
        if nack.code is m.ErrorCode.BAD_CRC:
            # The board saw a damaged frame, maybe ours. A hint: resend an idempotent request
            # now rather than at its timeout. It ends the request only if it names this very
            # request (seq and id) and no attempt is left.
            if request.IDEMPOTENT:
                pending.inbox.put(_Outcome(resend=True, error_if_final=error if matches else None))
                return
            if not matches:
                return
        if not matches:
            self._count(stale_replies=1)
            return
        pending.inbox.put(_Outcome(error=error))

    def _on_stream(self, frame: Frame, now: float) -> None:
        with self._lock:
            last = self._last_stream_seq
            self._last_stream_seq = frame.seq
        lost = 0 if last is None else (frame.seq - last - 1) & _SEQ_MASK
        self._count(stream_frames=1, stream_lost=lost)
        cls = m.BY_ID[frame.msg_id]
        try:
            message = cls.decode(frame.body)
        except DecodeError as exc:
            log.warning("utrf link: dropped a %s frame: %s", cls.NAME, exc)
            self._count(decode_errors=1)
            return
        self._deliver(Telemetry(message, frame.seq, now))  # type: ignore[arg-type]

    def _on_boot(self, frame: Frame, now: float) -> None:
        with self._lock:
            self._last_stream_seq = frame.seq
        boot: m.Boot | None
        try:
            boot = m.Boot.decode(frame.body)
        except DecodeError as exc:
            log.warning("utrf link: the board reset; its boot message does not decode: %s", exc)
            boot = None
        error = BoardResetError(boot)
        with self._lock:
            self._reset = error
            self._identity = None
            pending = self._pending
        if pending is not None:
            pending.inbox.put(_Outcome(error=error))
        if boot is not None:
            self._deliver(Telemetry(boot, frame.seq, now))

    def _deliver(self, item: Telemetry) -> None:
        while True:
            try:
                self.telemetry.put_nowait(item)
                break
            except queue.Full:
                with contextlib.suppress(queue.Empty):
                    self.telemetry.get_nowait()
                self._count(telemetry_dropped=1)
        with self._lock:
            callbacks = list(self._callbacks)
        for callback in callbacks:
            try:
                callback(item)
            except Exception:
                log.exception("utrf link: telemetry callback %r failed", callback)


def _version_and_hash(body: bytes, what: str) -> tuple[int, int]:
    """protocol_version (u16) and schema_hash (u32): the fixed head of identity and boot."""
    if len(body) < 6:
        raise DecodeError(what, None, f"body of {len(body)} bytes is too short for its version")
    return int.from_bytes(body[0:2], "little"), int.from_bytes(body[2:6], "little")
