"""A :class:`~utrf.protocol.link.Link` for a driven emulated board, in simulated time.

``Link`` waits on the wall clock from its own threads. ``SimLink`` has no threads: a request
runs the board (``EmulatedBoard(realtime=False)``) until its reply arrives, and
:meth:`SimLink.sleep` runs it for the time asked, sending heartbeats as ``Link`` would. Both
drive the same :class:`~utrf.protocol.engine.Engine`, so ``SimLink`` keeps ``Link``'s rules
and errors (seq, resends of idempotent requests after the reply timeout, the ``BAD_CRC``
hint, ``NackError``, ``BoardResetError`` until the next :meth:`handshake`, stream loss
counted from seq gaps), and it is the :class:`Clock` of the :class:`~utrf.hand.Hand` that
uses it, so a trajectory streamed over it runs in simulated time: as fast as the machine goes
and the same on every run for a seed.

    with EmulatedBoard(realtime=False) as board:
        with Hand.emulated(board) as hand:      # a Hand over a SimLink
            hand.pose("shaka", duration=1.0)

Replies and stream frames are noticed at the end of the board's exchange period (250 µs by
default, the finest step a driven board takes) in which their last byte came; that bounds the
resolution of latencies measured here. The board runs in C from one frame to the next
(:meth:`EmulatedBoard.run_until_output`): Python looks at the output only when a frame has
come, and for heartbeats.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.engine import (
    Done,
    Engine,
    EngineDriver,
    LinkStats,
    Telemetry,
    Transmit,
    call_each,
)
from utrf.protocol.errors import DisconnectedError

if TYPE_CHECKING:
    from utrf.emulator import EmulatedBoard

R = TypeVar("R", bound=Message)
#: longest stretch of simulated time run between two looks at the board's output while sleeping
#: (each frame that comes is looked at when it has come, whatever this is)
PUMP_INTERVAL_S = 0.1


class SimLink(EngineDriver):
    """Requests, replies and telemetry over a driven board's UART0, in simulated time."""

    def __init__(
        self,
        board: EmulatedBoard,
        *,
        retries: int = m.RETRIES,
        heartbeat_period_s: float | None = m.HEARTBEAT_PERIOD_S,
        on_telemetry: Callable[[Telemetry], None] | None = None,
    ) -> None:
        self.pump_interval_s = PUMP_INTERVAL_S  # a caller that samples slower may widen it
        if board.realtime:
            raise ValueError(
                "SimLink needs a driven board (EmulatedBoard(realtime=False)); "
                f"connect to a real-time board with Link.open({board.url!r})"
            )
        self._engine = Engine(
            retries=retries, heartbeat_period_s=heartbeat_period_s, now=board.sim_time
        )
        self.board = board
        self._callbacks: list[Callable[[Telemetry], None]] = []
        if on_telemetry is not None:
            self._callbacks.append(on_telemetry)

    # --- Link's interface ----------------------------------------------------------------

    def stats(self) -> LinkStats:
        return self._engine.stats()

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        self._callbacks.append(callback)

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None:
        self._callbacks.remove(callback)

    def close(self) -> None:
        self._engine.fail(DisconnectedError("the link was closed"))

    def request(
        self, msg: Request[R], *, timeout_s: float | None = None, retries: int | None = None
    ) -> R:
        """As :meth:`Link.request <utrf.protocol.link.Link.request>`, timeouts in simulated s."""
        self._engine.start_request(msg, timeout_s=timeout_s, retries=retries)
        frame = self._drive()
        return msg.decode_reply(frame.body)

    def handshake(self, timeout_s: float = 3.0) -> m.Identity:
        """As :meth:`Link.handshake <utrf.protocol.link.Link.handshake>`, in simulated s."""
        self._engine.start_handshake(timeout_s, self.now())
        return self._drive()

    # --- the Clock -----------------------------------------------------------------------

    def now(self) -> float:
        return self.board.sim_time

    def timestamp(self) -> float:
        return self.board.sim_time

    def sleep(self, seconds: float) -> None:
        """Run the board for ``seconds`` of simulated time, with heartbeats, delivering its
        frames to the callbacks as they arrive (at the end of the exchange that brought their
        last byte). The board moves in whole exchange periods: the sleep ends within half of
        one of ``seconds``."""
        end = self.now() + seconds
        period = self.board.exchange_period
        while self.now() < end - period / 2:
            now = self.now()
            step = min(end - now, self.pump_interval_s)
            heartbeat = self._engine.heartbeat(now)
            if heartbeat is not None:
                self._send(heartbeat)
            due = self._engine.heartbeat_due()
            if due is not None:
                step = min(step, due - now)
            # whole exchanges, at least one (a step shorter than a clock cycle would not move
            # the board), the nearest to the step: the sleep ends within half an exchange. The
            # frames that come meanwhile go to the engine as each one ends.
            self.board.run_until_output(max(round(step / period), 1) * period, self._pump_on)
            self._pump()

    # --- driving the engine ----------------------------------------------------------------

    def _drive(self) -> Any:
        """Write what the engine asks and run the board until its request ends."""
        engine = self._engine
        try:
            now = self.now()
            action = engine.poll(now)
            while not isinstance(action, Done):
                if isinstance(action, Transmit):
                    self._send(action)
                    now = self.now()
                else:  # Wait: run the board until something arrives or the time comes
                    until = self._heartbeat_until(action.until, now)
                    arrived = self._pump() or self.board.run_until_output(
                        until - self.now(), self._pump
                    )
                    # run_until moves in whole exchanges of whole cycles: when it gave up, the
                    # time has come, even if rounding left it a fraction of a cycle short
                    now = self.now() if arrived else max(self.now(), until)
                action = engine.poll(now)
            return action.result()
        except BaseException:
            engine.abandon()
            raise

    def _heartbeat_until(self, until: float, now: float) -> float:
        """A heartbeat if one is due at ``now`` (a request waiting on its resends does not keep
        the board's watchdog fed); then ``until``, or the next heartbeat's time if sooner.
        ``now`` is the drive's clock, which may be a fraction of a cycle past the board's."""
        heartbeat = self._engine.heartbeat(now)
        if heartbeat is not None:
            self._send(heartbeat)
        due = self._engine.heartbeat_due()
        return until if due is None else min(until, due)

    def _send(self, tx: Transmit) -> None:
        self.board.write(tx.data)
        self._engine.sent(tx, self.now())

    def _pump_on(self) -> bool:
        """Deliver the frames that came; go on running."""
        self._pump()
        return False

    def _pump(self) -> bool:
        """Hand what the board has sent to the engine and the callbacks; returns whether the
        request in flight has news."""
        data = self.board.read()
        if data:
            now = self.now()
            for item in self._engine.receive(data, now):
                call_each(list(self._callbacks), item)
        return self._engine.settled
