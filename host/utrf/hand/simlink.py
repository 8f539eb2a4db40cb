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

Replies and stream frames are noticed at the board's exchange period (250 µs by default), the
finest step a driven board takes; that bounds the resolution of latencies measured here.
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
PUMP_INTERVAL_S = 1e-3


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
        frames to the callbacks as they arrive (to within ``PUMP_INTERVAL_S``). The board moves
        in whole exchange periods: the sleep ends within half of one of ``seconds``."""
        end = self.now() + seconds
        period = self.board.exchange_period
        while self.now() < end - period / 2:
            now = self.now()
            step = min(end - now, PUMP_INTERVAL_S)
            heartbeat = self._engine.heartbeat(now)
            if heartbeat is not None:
                self._send(heartbeat)
            due = self._engine.heartbeat_due()
            if due is not None:
                step = min(step, due - now)
            # whole exchanges, at least one (a step shorter than a clock cycle would not move
            # the board), the nearest to the step: the sleep ends within half an exchange
            self.board.run_for(max(round(step / period), 1) * period)
            self._pump()

    # --- driving the engine ----------------------------------------------------------------

    def _drive(self) -> Any:
        """Write what the engine asks and run the board until its request ends."""
        engine = self._engine
        try:
            action = engine.poll(self.now())
            while not isinstance(action, Done):
                if isinstance(action, Transmit):
                    self._send(action)
                    now = self.now()
                else:  # Wait: run the board until something arrives or the time comes
                    arrived = self.board.run_until(
                        lambda _b: self._pump(), action.until - self.now()
                    )
                    # run_until moves in whole exchanges of whole cycles: when it gave up, the
                    # time has come, even if rounding left it a fraction of a cycle short
                    now = self.now() if arrived else max(self.now(), action.until)
                action = engine.poll(now)
            return action.result()
        except BaseException:
            engine.abandon()
            raise

    def _send(self, tx: Transmit) -> None:
        self.board.write(tx.data)
        self._engine.sent(tx, self.now())

    def _pump(self) -> bool:
        """Hand what the board has sent to the engine and the callbacks; returns whether the
        request in flight has news."""
        data = self.board.read()
        if data:
            now = self.now()
            for item in self._engine.receive(data, now):
                call_each(list(self._callbacks), item)
        return self._engine.settled
