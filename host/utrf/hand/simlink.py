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
come, and for heartbeats. :meth:`SimLink.sleep_each` samples at given times with the board
running on ahead to the next on a thread of its own while Python works (the same run and
the same stamps to the cycle; the grasp hold's samples).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterable
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
    from utrf.hand.simlink_stops import Stops

R = TypeVar("R", bound=Message)
T = TypeVar("T")
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
        self._heartbeat: Transmit | None = None  # made for a run ahead, not yet gone
        self._at: float | None = None  # the time a message delivered late arrived at
        self._arrived: list[tuple[bytes, float]] = []  # a run ahead's bytes, stamped
        self._items: list[Telemetry] = []  # messages the engine took, not yet delivered
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
        return self.board.sim_time if self._at is None else self._at

    def timestamp(self) -> float:
        return self.now()

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
            heartbeat = self._heartbeat_at(now)
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

    def sleep_each(
        self, ends: Iterable[float], take: Callable[[], T | None]
    ) -> Generator[T, None, None]:
        """Sleep to each of ``ends`` (simulated s, rising) as :meth:`sleep` would, to the cycle,
        with the board running ahead: at each end ``take()`` is called with the board stopped
        there (to read or hit the plant; not the link), and its value is yielded once the
        frames that came up to there have been delivered to the callbacks, each stamped with
        the end of the exchange that brought its last byte as :meth:`sleep` stamps it. The
        board already runs on to the next end on its own thread (``run_ahead``) while the
        engine, the callbacks and the caller work. ``take()`` giving None ends it there. Ends
        further apart than half a heartbeat period are slept plainly."""
        it = iter(ends)
        end = next(it, None)
        ahead = end is not None and self._ahead(end)
        try:
            while end is not None:
                if ahead:
                    self._join_ahead(end)
                ahead = False
                value = take()
                end = None if value is None else next(it, None)
                if end is not None:
                    ahead = self._ahead(end)
                self._deliver_arrived()
                if value is not None:
                    yield value
        finally:
            if ahead:  # the caller stopped early: the frames that came still go to the engine
                self._join_ahead(None)
            self._deliver_arrived()

    def stops_each(
        self, ends: Iterable[float], take: Callable[[], T | None], stops: Stops
    ) -> Generator[T, None, None]:
        """:meth:`sleep_each` with what ``take()`` does to the plant done by the harness at
        each end (``stops``), the board running through many ends a batch: the same samples,
        fewer stops (:mod:`utrf.hand.simlink_stops`)."""
        from utrf.hand.simlink_stops import stops_each

        return stops_each(self, ends, take, stops)

    def _ahead(self, end: float) -> bool:
        """Start the board running to ``end`` as :meth:`sleep` would run it; False when it is
        slept plainly (what arrived is delivered first) or no exchange is due."""
        period = self.board.exchange_period
        now = self.now()
        seconds = end - now
        if seconds < period / 2:  # sleep() would not move the board: its loop ends at once
            return False
        hb_period = self._engine.heartbeat_period_s
        if hb_period is not None and seconds > min(hb_period / 2, self.pump_interval_s):
            self._deliver_arrived()
            self.sleep(seconds)
            return False
        # the end sleep() reaches: whole exchanges, the nearest to the end, at least one
        seconds = max(round(seconds / period), 1) * period
        last = self.board.exchanges_end(seconds)
        due = self._engine.heartbeat_due()
        if due is not None and due <= last and self._arrived:
            # the frames not taken yet may move it (an ack, a reset): the engine takes them
            # first; otherwise it can only be later, past this run, and they wait
            self._take_arrived()
            due = self._engine.heartbeat_due()
        send = None
        # a heartbeat that falls due by the run's last exchange goes out within it, at the
        # first exchange's end at or past its time, where sleep() sends it
        if due is not None and due <= last:
            if self._heartbeat is None:
                self._heartbeat = self._engine.heartbeat(max(due, now))
            if self._heartbeat is not None:
                send = (self._heartbeat.data, due)
        self.board.run_ahead(seconds, send)
        return True

    def _join_ahead(self, end: float | None) -> None:
        """Wait for the run ahead: its bytes wait for the engine, cut where sleep() would
        have looked and stamped there, and its heartbeat is counted. A run that stopped
        short of ``end`` (a crash, its marks full) goes on plainly."""
        board = self.board
        run = board.run_ahead_join()
        data = board.read()
        at = 0
        for n, t in run.marks:
            self._arrived.append((data[at:n], t))
            at = n
        self._arrived.append((data[at:], self.now()))
        if self._heartbeat is not None and run.sent_at is not None:
            self._engine.sent(self._heartbeat, run.sent_at)
            self._heartbeat = None
        if not run.done and end is not None:
            self._deliver_arrived()
            self.sleep(end - self.now())

    def _take_arrived(self) -> None:
        """The engine takes the bytes a run ahead brought; its messages wait for delivery."""
        for data, t in self._arrived:
            self._items += self._engine.receive(data, t)
        self._arrived = []

    def _deliver_arrived(self, until: float | None = None) -> None:
        """The callbacks, each message at its own time: the clock reads its arrival while
        they run (the board may be ahead by then). ``until``: only those that arrived by then
        (s); the rest wait."""
        self._take_arrived()
        items, self._items = self._items, []
        if until is not None:
            n = next((i for i, item in enumerate(items) if item.received_s > until), len(items))
            items, self._items = items[:n], items[n:]
        try:
            for item in items:
                self._at = item.received_s
                call_each(list(self._callbacks), item)
        finally:
            self._at = None

    def _heartbeat_at(self, now: float) -> Transmit | None:
        """The heartbeat to send at ``now`` if one is due: the one a run ahead made and could
        not send (it stopped short), else the engine's."""
        if self._heartbeat is None:
            return self._engine.heartbeat(now)
        due = self._engine.heartbeat_due()
        if due is None or due > now:
            return None
        tx, self._heartbeat = self._heartbeat, None
        return tx

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
        heartbeat = self._heartbeat_at(now)
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
