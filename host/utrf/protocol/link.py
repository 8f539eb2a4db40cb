"""Requests and replies over a line to the board: :class:`Link`.

One request is in flight at a time; its reply echoes its seq. A request that gets no reply
within its ``REPLY_TIMEOUT_S`` is resent (same seq, same bytes) when it is idempotent, up to
``retries`` times (a ``BAD_CRC`` nack naming it has it resent at once, up to as many times
again), and raises :class:`ReplyTimeout` after that; a request that is not idempotent is
never resent. The board's own frames (``state`` stream, ``fault``, ``boot``)
carry seqs with ``BOARD_SEQ_FLAG`` set from a running counter; they go to :attr:`Link.telemetry`
(a queue) and to callbacks, from the reader thread, so they never wait for a request and a
request never waits for them. A gap in their seqs counts as lost frames.

    with Link.open("socket://127.0.0.1:5555") as link:
        identity = link.handshake()          # SchemaMismatchError if the firmware differs
        link.request(SetTelemetry(rate_hz=100))
        item = link.telemetry.get(timeout=1.0)  # Telemetry(message=State(...), ...)

Thread-safe: any thread may call :meth:`Link.request`; calls are served one at a time.

The rules themselves are :class:`~utrf.protocol.engine.Engine`'s; ``Link`` drives it on the
wall clock: the transport's reader thread feeds it what arrives, a request waits on a
condition variable for its reply or its deadline, and a thread of its own sends heartbeats.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.engine import (
    Done,
    Engine,
    EngineDriver,
    LinkStats,
    StreamMessage,
    Telemetry,
    Transmit,
    Wait,
    call_each,
)
from utrf.protocol.errors import (
    DisconnectedError,
    NoAnswerError,
    NotABoardError,
    PortBusyError,
    ReplyTimeout,
)
from utrf.protocol.transport import SerialTransport, Transport

__all__ = ["Link", "LinkStats", "StreamMessage", "Telemetry"]

R = TypeVar("R", bound=Message)
log = logging.getLogger(__name__)


class Link(EngineDriver):
    """Request/response and telemetry over a :class:`Transport`.

    ``heartbeat_period_s``: after a successful :meth:`handshake`, send a ``heartbeat`` when
    nothing else went out for this long (None: never), so the board's host-silence watchdog
    stays fed. ``retries``: resends of an idempotent request after a timeout.
    ``telemetry_queue_size``: when :attr:`telemetry` is full the oldest items are dropped
    (counted as ``telemetry_dropped``); 0: no queue, the callbacks only (what a Hand uses).
    Callbacks (``on_telemetry``) run on the reader thread: keep them short.
    ``on_telemetry_batch`` gets the items of each read together, after they were queued and
    given to the per-item callbacks (a consumer of a fast stream takes a read's samples at
    once: the Hand).
    """

    def __init__(
        self,
        transport: Transport,
        *,
        retries: int = m.RETRIES,
        heartbeat_period_s: float | None = m.HEARTBEAT_PERIOD_S,
        telemetry_queue_size: int = 1024,
        on_telemetry: Callable[[Telemetry], None] | None = None,
        on_telemetry_batch: Callable[[list[Telemetry]], None] | None = None,
    ) -> None:
        self._engine = Engine(
            retries=retries, heartbeat_period_s=heartbeat_period_s, now=time.monotonic()
        )
        self.telemetry: queue.Queue[Telemetry] = queue.Queue(maxsize=max(telemetry_queue_size, 1))
        self._queue_telemetry = telemetry_queue_size > 0
        self._callbacks: list[Callable[[Telemetry], None]] = []
        if on_telemetry is not None:
            self._callbacks.append(on_telemetry)
        self._batch_callback = on_telemetry_batch
        self._transport = transport
        self._cond = threading.Condition(threading.Lock())  # guards the engine and callbacks
        self._request_lock = threading.Lock()  # one request in flight
        self._stop = threading.Event()
        self._heard = bytearray()  # the first bytes received (see _no_identity)
        self._heartbeat_thread: threading.Thread | None = None
        transport.start(self._on_data, self._on_close)
        if heartbeat_period_s is not None:
            self._heartbeat_thread = threading.Thread(
                target=self._heartbeat_loop, name="utrf-heartbeat", daemon=True
            )
            self._heartbeat_thread.start()

    @classmethod
    def open(cls, url: str, baudrate: int = m.DEFAULT_BAUD, **kwargs: Any) -> Link:
        """A link over ``serial.serial_for_url(url)``; keyword arguments go to :class:`Link`."""
        return cls(SerialTransport(url, baudrate), **kwargs)

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
    def read_linger_s(self) -> float:
        """How long the reader waits after each read so that one read carries many frames
        (0, the default: every frame is read as it comes). A request's reply is read at once
        whatever this is (:meth:`Transport.awaiting_reply`); stream frames, faults and
        heartbeat acks may then wait this long. For consumers of a fast stream that take it
        in batches (the dashboard)."""
        return self._transport.linger_s

    @read_linger_s.setter
    def read_linger_s(self, value: float) -> None:
        self._transport.linger_s = value

    def read_soon(self) -> None:
        """End the reader's linger: what has arrived is read now, and if nothing has, what
        arrives next (a consumer that wants the stream's newest sample at once)."""
        self._transport.read_soon()

    def stats(self) -> LinkStats:
        with self._cond:
            return self._engine.stats()

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        with self._cond:
            self._callbacks.append(callback)

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        with self._cond:
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
        with self._request_lock:
            with self._cond:
                self._engine.start_request(msg, timeout_s=timeout_s, retries=retries)
            frame = self._drive()
        return msg.decode_reply(frame.body)

    def handshake(self, timeout_s: float = 3.0) -> m.Identity:
        """Ask the board who it is, and check that it speaks this host's protocol.

        Sends ``identify`` until a reply comes or ``timeout_s`` passes (a board that just
        reset may still be in its bootloader). Clears a pending :class:`BoardResetError`:
        this is how the host reconnects after a reset. Raises :class:`SchemaMismatchError`
        naming both protocol versions and schema hashes when the firmware was built from
        another spec; the first two fields of ``identity`` keep their place in every version.
        When no UTRF frame ever came, says what was on the line instead: :class:`PortBusyError`
        (the peer said ``utrf busy: ...``: the emulated board has a host already),
        :class:`NotABoardError` (bytes that are no frame, or a line closed without a word),
        :class:`NoAnswerError` (silence).
        """
        start = time.monotonic()
        try:
            with self._request_lock:
                with self._cond:
                    self._engine.start_handshake(timeout_s, start)
                return self._drive()
        except (ReplyTimeout, DisconnectedError) as exc:
            raise self._no_identity(exc, time.monotonic() - start) from exc

    #: the peer's first bytes kept to say what answered when no board did
    HEARD_KEPT = 200
    #: how a peer that refuses a second host says so: one text line, then it closes the line
    BUSY_PREFIX = b"utrf busy: "

    def _no_identity(self, exc: ReplyTimeout | DisconnectedError, waited: float) -> Exception:
        """The handshake failed: say what was on the line, when no UTRF frame ever came."""
        with self._cond:
            stats = self._engine.stats()
            heard = bytes(self._heard)
        if stats.rx_frames:
            return exc  # a board spoke: the error as it is
        where = getattr(self._transport, "url", "the line")
        gone = isinstance(exc, DisconnectedError)
        if heard.startswith(self.BUSY_PREFIX):
            line = heard[len(self.BUSY_PREFIX) :].split(b"\n", 1)[0].decode("ascii", "replace")
            return PortBusyError(f"{where}: {line}")
        if heard:
            text = heard[:60].decode("ascii", "backslashreplace")
            return NotABoardError(
                f"not a UTRF board (no identity answer on {where}): it sent {len(heard)}"
                f"{'+' if len(heard) >= self.HEARD_KEPT else ''} bytes that are no UTRF frame "
                f"({text!r}{'...' if len(heard) > 60 else ''})"
                + (" and closed the line" if gone else "")
                + ": is it the right port, is --baud the board's?"
            )
        if isinstance(exc, DisconnectedError):
            return NotABoardError(
                f"not a UTRF board (no identity answer on {where}): the line closed without a "
                f"word ({exc})"
            )
        return NoAnswerError(
            f"no answer on {where} to identify in {waited:.1f} s ({exc.attempts} attempts): is "
            "the board powered, is it the right port, is another program using it?",
            exc,
        )

    # --- driving the engine ----------------------------------------------------------------

    def _drive(self) -> Any:
        """Write what the engine asks and wait on the wall clock until its request ends."""
        engine, cond = self._engine, self._cond
        try:
            with self._transport.awaiting_reply():
                return self._drive_engine(engine, cond)
        except BaseException:
            with cond:
                engine.abandon()
            raise

    def _drive_engine(self, engine: Engine, cond: threading.Condition) -> Any:
        sent: Transmit | None = None
        while True:
            with cond:
                now = time.monotonic()
                if sent is not None:
                    engine.sent(sent, now)
                action = engine.poll(now)
                while isinstance(action, Wait):
                    cond.wait(action.until - now)  # the reader notifies what arrives
                    now = time.monotonic()
                    action = engine.poll(now)
            if isinstance(action, Done):
                return action.result()
            self._write(action.data)
            sent = action

    def _write(self, data: bytes) -> None:
        try:
            self._transport.write(data)
        except DisconnectedError as exc:
            self._fail(exc)
            raise

    def _fail(self, error: DisconnectedError) -> None:
        with self._cond:
            self._engine.fail(error)
            self._cond.notify_all()

    # --- heartbeat -----------------------------------------------------------------------

    def _heartbeat_loop(self) -> None:
        engine = self._engine
        while not self._stop.is_set():
            with self._cond:
                now = time.monotonic()
                tx = engine.heartbeat(now)
                due = engine.heartbeat_due()
                period = engine.heartbeat_period_s or m.HEARTBEAT_PERIOD_S
            if tx is None:
                self._stop.wait(period if due is None else min(due - now, period))
                continue
            try:
                self._write(tx.data)
            except DisconnectedError:
                return
            with self._cond:
                engine.sent(tx, time.monotonic())

    # --- receiving (reader thread) -------------------------------------------------------

    def _on_close(self, error: BaseException | None) -> None:
        reason = f"the line went away: {error}" if error else "the line was closed"
        self._fail(DisconnectedError(reason))

    def _on_data(self, data: bytes) -> None:
        now = time.monotonic()
        engine, cond = self._engine, self._cond
        with cond:
            if len(self._heard) < self.HEARD_KEPT:
                self._heard += data[: self.HEARD_KEPT - len(self._heard)]
                busy = self._heard.startswith(self.BUSY_PREFIX) and b"\n" in self._heard
                if busy and not engine.stats().rx_frames:  # turned away: no need to wait
                    engine.fail(PortBusyError("turned away"))
                    cond.notify_all()
            events = engine.frames(data)
        items: list[Telemetry] = []
        for event in events:
            with cond:
                item = engine.handle(event, now)
                if engine.settled:
                    cond.notify_all()
            if item is not None:
                self._deliver(item)
                items.append(item)
        batch = self._batch_callback
        if items and batch is not None:
            try:
                batch(items)
            except Exception:
                log.exception("utrf link: telemetry callback %r failed", batch)

    def _deliver(self, item: Telemetry) -> None:
        while self._queue_telemetry:
            try:
                self.telemetry.put_nowait(item)
                break
            except queue.Full:
                with contextlib.suppress(queue.Empty):
                    self.telemetry.get_nowait()
                with self._cond:
                    self._engine.count("telemetry_dropped")
        with self._cond:
            callbacks = list(self._callbacks)
        call_each(callbacks, item)
