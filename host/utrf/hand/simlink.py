"""A :class:`~utrf.protocol.link.Link` for a driven emulated board, in simulated time.

``Link`` waits on the wall clock from its own threads. ``SimLink`` has no threads: a request
runs the board (``EmulatedBoard(realtime=False)``) until its reply arrives, and
:meth:`SimLink.sleep` runs it for the time asked, sending heartbeats as ``Link`` would. It
keeps ``Link``'s rules and errors (seq, resends of idempotent requests after the reply
timeout, the ``BAD_CRC`` hint, ``NackError``, ``BoardResetError`` until the next
:meth:`handshake`, stream loss counted from seq gaps), and it is the :class:`Clock` of the
:class:`~utrf.hand.Hand` that uses it, so a trajectory streamed over it runs in simulated
time: as fast as the machine goes and the same on every run for a seed.

    with EmulatedBoard(realtime=False) as board:
        with Hand.emulated(board) as hand:      # a Hand over a SimLink
            hand.pose("shaka", duration=1.0)

Replies and stream frames are noticed at the board's exchange period (250 µs by default), the
finest step a driven board takes; that bounds the resolution of latencies measured here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, TypeVar

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
from utrf.protocol.link import LinkStats, Telemetry

if TYPE_CHECKING:
    from utrf.emulator import EmulatedBoard

log = logging.getLogger(__name__)
R = TypeVar("R", bound=Message)
_SEQ_MASK = m.BOARD_SEQ_FLAG - 1
_STREAM_IDS = {m.State.ID, m.Fault.ID, m.Boot.ID}
#: longest stretch of simulated time run between two looks at the board's output while sleeping
PUMP_INTERVAL_S = 1e-3


class SimLink:
    """Requests, replies and telemetry over a driven board's UART0, in simulated time."""

    def __init__(
        self,
        board: EmulatedBoard,
        *,
        retries: int = m.RETRIES,
        heartbeat_period_s: float | None = m.HEARTBEAT_PERIOD_S,
        on_telemetry: Callable[[Telemetry], None] | None = None,
    ) -> None:
        if board.realtime:
            raise ValueError(
                "SimLink needs a driven board (EmulatedBoard(realtime=False)); "
                f"connect to a real-time board with Link.open({board.url!r})"
            )
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if heartbeat_period_s is not None and heartbeat_period_s <= 0:
            raise ValueError(
                f"heartbeat_period_s must be positive or None, got {heartbeat_period_s}"
            )
        self.board = board
        self.retries = retries
        self.heartbeat_period_s = heartbeat_period_s
        self._callbacks: list[Callable[[Telemetry], None]] = []
        if on_telemetry is not None:
            self._callbacks.append(on_telemetry)
        self._decoder = FrameDecoder()
        self._stats = LinkStats()
        self._seq = 0
        self._pending: tuple[int, Request[Message]] | None = None
        self._outcome: Frame | BaseException | str | None = None
        self._heartbeat_seqs: set[int] = set()
        self._last_stream_seq: int | None = None
        self._last_tx = board.sim_time
        self._identity: m.Identity | None = None
        self._reset: BoardResetError | None = None
        self._closed: DisconnectedError | None = None

    # --- Link's interface ----------------------------------------------------------------

    @property
    def identity(self) -> m.Identity | None:
        return self._identity

    def stats(self) -> LinkStats:
        return self._stats

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        self._callbacks.append(callback)

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        self._callbacks.remove(callback)

    def close(self) -> None:
        if self._closed is None:
            self._closed = DisconnectedError("the link was closed")

    def __enter__(self) -> SimLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def request(
        self, msg: Request[R], *, timeout_s: float | None = None, retries: int | None = None
    ) -> R:
        """As :meth:`Link.request <utrf.protocol.link.Link.request>`, timeouts in simulated s."""
        if not isinstance(msg, Request):
            raise TypeError(f"{type(msg).__name__} is not a request (host_to_board) message")
        body = msg.encode()
        self._check_usable()
        frame = self._exchange(msg, body, timeout_s, retries)
        return type(msg).REPLY.decode(frame.body)  # type: ignore[return-value]

    def handshake(self, timeout_s: float = 3.0) -> m.Identity:
        """As :meth:`Link.handshake <utrf.protocol.link.Link.handshake>`, in simulated s."""
        if self._closed is not None:
            raise self._closed
        deadline = self.now() + timeout_s
        self._reset = None
        self._write(b"\x00")
        attempts = 0
        while True:
            remaining = deadline - self.now()
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
                self._reset = None
                continue
            break
        if len(frame.body) < 6:
            raise DecodeError("identity", None, f"body of {len(frame.body)} bytes is too short")
        version = int.from_bytes(frame.body[0:2], "little")
        schema = int.from_bytes(frame.body[2:6], "little")
        if (version, schema) != (m.PROTOCOL_VERSION, m.SCHEMA_HASH):
            raise SchemaMismatchError(m.PROTOCOL_VERSION, m.SCHEMA_HASH, version, schema)
        self._identity = m.Identity.decode(frame.body)
        return self._identity

    # --- the Clock -----------------------------------------------------------------------

    def now(self) -> float:
        return self.board.sim_time

    def timestamp(self) -> float:
        return self.board.sim_time

    def sleep(self, seconds: float) -> None:
        """Run the board for ``seconds`` of simulated time, with heartbeats, delivering its
        frames to the callbacks as they arrive (to within ``PUMP_INTERVAL_S``). The board moves
        in whole exchange periods: the sleep ends within half of one of ``seconds``."""
        end = self.now() + seconds
        period = self.board.exchange_period
        while self.now() < end - period / 2:
            now = self.now()
            step = min(end - now, PUMP_INTERVAL_S)
            if self._heartbeats_on():
                assert self.heartbeat_period_s is not None
                due = self._last_tx + self.heartbeat_period_s
                if due <= now:
                    self._send_heartbeat()
                    due = now + self.heartbeat_period_s
                step = min(step, due - now)
            # whole exchanges, at least one (a step shorter than a clock cycle would not move
            # the board), the nearest to the step: the sleep ends within half an exchange
            self.board.run_for(max(round(step / period), 1) * period)
            self._pump()

    # --- internals -----------------------------------------------------------------------

    def _check_usable(self) -> None:
        if self._closed is not None:
            raise self._closed
        if self._reset is not None:
            raise self._reset

    def _heartbeats_on(self) -> bool:
        return (
            self.heartbeat_period_s is not None
            and self._identity is not None
            and self._reset is None
            and self._closed is None
        )

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (self._seq + 1) & _SEQ_MASK
        return seq

    def _count(self, **deltas: int) -> None:
        self._stats = replace(
            self._stats, **{k: getattr(self._stats, k) + v for k, v in deltas.items()}
        )

    def _write(self, data: bytes) -> None:
        self.board.write(data)
        self._last_tx = self.now()

    def _send_heartbeat(self) -> None:
        seq = self._next_seq()
        self._heartbeat_seqs.add(seq)
        if len(self._heartbeat_seqs) > 32:
            self._heartbeat_seqs.pop()
        self._write(encode_frame(seq, m.Heartbeat.ID))
        self._count(tx_frames=1, heartbeats=1)

    def _exchange(
        self, msg: Request[Message], body: bytes, timeout_s: float | None, retries: int | None
    ) -> Frame:
        timeout = msg.REPLY_TIMEOUT_S if timeout_s is None else timeout_s
        allowed = 1 + ((self.retries if retries is None else retries) if msg.IDEMPOTENT else 0)
        seq = self._next_seq()
        frame = encode_frame(seq, msg.ID, body)
        self._pending = (seq, msg)
        try:
            attempt = 0
            while True:
                attempt += 1
                if attempt > 1:
                    self._count(retries=1)
                self._outcome = None
                self._write(frame)
                self._count(tx_frames=1)
                self.board.run_until(lambda _b: self._pump() is not None, timeout)
                outcome = self._outcome
                if outcome is None:
                    if attempt < allowed:
                        continue
                    self._count(timeouts=1)
                    raise ReplyTimeout(msg, timeout, attempt)
                if isinstance(outcome, Frame):
                    return outcome
                if isinstance(outcome, str):  # "resend": a BAD_CRC hint
                    if attempt < allowed:
                        continue
                    raise NackError(m.ErrorCode.BAD_CRC, 0, msg)
                raise outcome
        finally:
            self._pending = None
            self._outcome = None

    def _pump(self) -> Frame | BaseException | str | None:
        """Decode what the board has sent; returns the pending request's outcome, if any."""
        data = self.board.read()
        if data:
            now = self.now()
            for event in self._decoder.feed(data):
                if isinstance(event, FrameError):
                    field = {
                        RxEvent.CRC_ERROR: "crc_errors",
                        RxEvent.FRAMING_ERROR: "framing_errors",
                        RxEvent.OVERSIZE: "oversize",
                    }[event.kind]
                    self._count(**{field: 1})
                else:
                    self._on_frame(event, now)
        return self._outcome

    def _settle(self, outcome: Frame | BaseException | str) -> None:
        if self._outcome is None or isinstance(self._outcome, str):
            self._outcome = outcome

    def _on_frame(self, frame: Frame, now: float) -> None:
        self._count(rx_frames=1)
        if frame.msg_id == m.Boot.ID:
            self._on_boot(frame, now)
            return
        if frame.msg_id in _STREAM_IDS and frame.seq & m.BOARD_SEQ_FLAG:
            self._on_stream(frame, now)
            return
        pending = self._pending
        if frame.msg_id == m.Nack.ID:
            self._on_nack(frame)
            return
        if pending is not None and frame.seq == pending[0]:
            request = pending[1]
            if frame.msg_id == type(request).REPLY.ID:
                if frame.msg_id == m.Ack.ID and frame.body != bytes([request.ID]):
                    self._count(stale_replies=1)
                    return
                self._settle(frame)
                return
            name = m.BY_ID[frame.msg_id].NAME if frame.msg_id in m.BY_ID else hex(frame.msg_id)
            self._settle(
                ProtocolError(
                    f"{request.NAME} was answered with {name}, expected {type(request).REPLY.NAME}"
                )
            )
            return
        if frame.msg_id == m.Ack.ID and frame.seq in self._heartbeat_seqs:
            self._heartbeat_seqs.discard(frame.seq)
            return
        self._count(stale_replies=1)

    def _on_nack(self, frame: Frame) -> None:
        try:
            nack = m.Nack.decode(frame.body)
        except DecodeError:
            self._count(decode_errors=1)
            return
        self._count(nacks=1)
        pending = self._pending
        if pending is None:
            return
        seq, request = pending
        matches = frame.seq == seq and nack.msg_id == request.ID
        if nack.code is m.ErrorCode.BAD_CRC:
            if request.IDEMPOTENT:
                self._settle("resend")
                return
            if not matches:
                return
        if not matches:
            self._count(stale_replies=1)
            return
        self._settle(NackError(nack.code, nack.detail, request))

    def _on_stream(self, frame: Frame, now: float) -> None:
        last = self._last_stream_seq
        self._last_stream_seq = frame.seq
        lost = 0 if last is None else (frame.seq - last - 1) & _SEQ_MASK
        self._count(stream_frames=1, stream_lost=lost)
        cls = m.BY_ID[frame.msg_id]
        try:
            message = cls.decode(frame.body)
        except DecodeError:
            self._count(decode_errors=1)
            return
        self._deliver(Telemetry(message, frame.seq, now))  # type: ignore[arg-type]

    def _on_boot(self, frame: Frame, now: float) -> None:
        self._last_stream_seq = frame.seq
        boot: m.Boot | None
        try:
            boot = m.Boot.decode(frame.body)
        except DecodeError:
            boot = None
        error = BoardResetError(boot)
        self._reset = error
        self._identity = None
        if self._pending is not None:
            self._settle(error)
        if boot is not None:
            self._deliver(Telemetry(boot, frame.seq, now))

    def _deliver(self, item: Telemetry) -> None:
        for callback in list(self._callbacks):
            try:
                callback(item)
            except Exception:  # as Link: one bad callback does not stop the others
                log.exception("utrf sim link: telemetry callback %r failed", callback)
