"""What the board reports: the state stream, faults, the board's reset, the telemetry log,
and the freshest state a wait can use."""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

from utrf.hand.errors import FingerFaultError
from utrf.hand.session import HandSession, log
from utrf.hand.state import STATE_CLOCK_WRAP_S, BoardClock, FaultEvent, HandState, TipModel
from utrf.hand.state_block import StateBlock
from utrf.hand.telemetry_log import TelemetryLog
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as m
from utrf.protocol.errors import NackError, ProtocolError
from utrf.protocol.link import Telemetry

#: default telemetry rate: a sample every 10 ms, 7 % of the line
DEFAULT_TELEMETRY_HZ = 100


class HandTelemetry:
    """The Hand's view of what its board reports (a part of :class:`~utrf.hand.Hand`).
    :meth:`on_frames` takes every stream frame, from the link's reader thread."""

    def __init__(
        self,
        session: HandSession,
        geometry: HandGeometry,
        fingers: tuple[str, ...],
        telemetry_hz: int = DEFAULT_TELEMETRY_HZ,
    ) -> None:
        if not 0 <= telemetry_hz <= m.MAX_TELEMETRY_HZ:
            raise ValueError(
                f"telemetry_hz must lie in 0..{m.MAX_TELEMETRY_HZ} Hz, got {telemetry_hz}"
            )
        self._session = session
        self._fingers = fingers
        self._telemetry_hz = int(telemetry_hz)
        self._lock = threading.Lock()  # telemetry arrives on the reader thread
        # Held while callbacks run, so an unsubscribe returns only once no call is under way
        # (re-entrant: a callback may unsubscribe itself).
        self._dispatch_lock = threading.RLock()
        self._board_clock = BoardClock(STATE_CLOCK_WRAP_S)  # the state's ms clock
        self._fault_clock = BoardClock()  # the fault message's µs clock
        self._tips = TipModel(geometry)
        self._status: m.Status | None = None  # the latest status (modes, faults)
        self._latest: HandState | None = None
        self._state_callbacks: list[Callable[[HandState], None]] = []
        self._block_callbacks: list[Callable[[StateBlock], None]] = []
        self._fault_callbacks: list[Callable[[FaultEvent], None]] = []
        self._faults_seen: list[FaultEvent] = []
        self._log: TelemetryLog | None = None

    # --- state ----------------------------------------------------------------------------------

    @property
    def telemetry_hz(self) -> int:
        return self._telemetry_hz

    @property
    def latest(self) -> HandState | None:
        """The most recent sample (telemetry or ``state()``), None before the first."""
        with self._lock:
            return self._latest

    @property
    def faults_seen(self) -> list[FaultEvent]:
        """Every ``fault`` message received since connecting (or ``forget_faults``)."""
        with self._lock:
            return list(self._faults_seen)

    def forget_faults(self) -> None:
        with self._lock:
            self._faults_seen.clear()

    def state(self) -> HandState:
        """Ask the board for its state now (``get_state``; and ``get_status`` when the
        sample names a status not received yet)."""
        msg = self._session.request(m.GetState())
        with self._lock:
            status = self._status
        if status is None or status.change != msg.status_seq:
            self._take_status(self._session.request(m.GetStatus()))
        host_time = self._session.clock.timestamp()
        with self._lock:
            st = self._state_of(msg, host_time)
            if self._latest is None or st.board_time >= self._latest.board_time:
                self._latest = st
        return st

    def poll_period(self) -> float:
        """How often a wait looks at the state: each sample at the stream's rate, between
        2 ms and 20 ms (20 ms without a stream: each look is then a get_state)."""
        period = 1.0 / self._telemetry_hz if self._telemetry_hz else 0.02
        return min(max(period, 0.002), 0.02)

    def fresh_state(self, previous: HandState | None) -> HandState:
        """The latest telemetry sample if it is newer than ``previous`` and recent; else ask."""
        self._session.check_alive()
        st = self.latest
        if (
            st is not None
            and self._telemetry_hz
            and (previous is None or st.board_time > previous.board_time)
            and self._session.clock.timestamp() - st.host_time < max(5.0 / self._telemetry_hz, 0.1)
        ):
            return st
        return self.state()

    # --- the stream -----------------------------------------------------------------------------

    def set_telemetry(self, rate_hz: int) -> None:
        """Stream the hand's state at ``rate_hz`` (0 stops; at most 500 Hz)."""
        if not 0 <= rate_hz <= m.MAX_TELEMETRY_HZ:
            raise ValueError(f"rate_hz must lie in 0..{m.MAX_TELEMETRY_HZ}, got {rate_hz}")
        self._session.request(m.SetTelemetry(rate_hz=int(rate_hz)))
        self._telemetry_hz = int(rate_hz)

    def resume(self) -> None:
        """After a handshake: the stream at the Hand's rate, and the board's status now."""
        self._session.request(m.SetTelemetry(rate_hz=self._telemetry_hz))
        self._take_status(self._session.request(m.GetStatus()))

    def silence(self) -> None:
        """Stop the stream on closing (the rate asked for is kept)."""
        self._session.request(m.SetTelemetry(rate_hz=0))

    def on_state(self, callback: Callable[[HandState], None]) -> Callable[[], None]:
        """Call ``callback(HandState)`` for every telemetry sample (from the link's reader
        thread on a real link: keep it short). Returns a function that unsubscribes; once it
        returns, the callback is not called again."""
        return self._subscribe(self._state_callbacks, callback)

    def on_states(self, callback: Callable[[StateBlock], None]) -> Callable[[], None]:
        """Call ``callback(StateBlock)`` with the telemetry samples of each read of the line,
        as arrays (every sample, in order; from the link's reader thread: keep it short).
        Costs the Hand no HandState per sample unless an ``on_state`` callback or the
        telemetry log asks for them. Returns a function that unsubscribes."""
        return self._subscribe(self._block_callbacks, callback)

    def on_fault(self, callback: Callable[[FaultEvent], None]) -> Callable[[], None]:
        """Call ``callback(FaultEvent)`` whenever a finger latches a fault. Returns a function
        that unsubscribes."""
        return self._subscribe(self._fault_callbacks, callback)

    def _subscribe(
        self, callbacks: list[Callable[[Any], None]], callback: Callable[[Any], None]
    ) -> Callable[[], None]:
        with self._lock:
            callbacks.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in callbacks:
                    callbacks.remove(callback)
            with self._dispatch_lock:
                pass  # a call under way has returned

        return unsubscribe

    def _dispatch(self, callbacks: list[Callable[[Any], None]], item: object) -> None:
        with self._dispatch_lock:
            for cb in list(callbacks):
                if cb in callbacks:  # not unsubscribed by an earlier callback
                    cb(item)

    def start_log(self, path: str | Path) -> TelemetryLog:
        """Log every telemetry sample to a CSV file (appended when its columns match)."""
        log_ = TelemetryLog(path, self._fingers)
        with self._lock:
            old, self._log = self._log, log_
        if old is not None:
            old.close()
        return log_

    def stop_log(self) -> None:
        with self._lock:
            old, self._log = self._log, None
        if old is not None:
            old.close()

    def _state_of(self, msg: m.State, host_time: float, seq: int | None = None) -> HandState:
        """A state message as a HandState, with the status and tips known now and its board
        time unwrapped (the caller holds the lock)."""
        return HandState.from_message(
            msg,
            self._fingers,
            self._status,
            self._tips,
            board_time=self._board_clock.unwrap(msg.board_time, host_time),
            host_time=host_time,
            seq=seq,
        )

    def _take_status(self, msg: m.Status) -> None:
        """A status (stream or get_status reply): the newest by change count is kept."""
        with self._lock:
            old = self._status
            if old is None or (msg.change - old.change) % 256 < 128:
                self._status = msg

    def on_frames(self, items: Sequence[Telemetry]) -> None:
        """The frames one read of the line brought, in order. The one place that chooses how
        a run of ``state`` samples is taken: with a per-sample consumer (an ``on_state``
        callback, the telemetry log) each becomes a HandState; without, the run is taken as
        arrays and only its newest becomes one (``Hand.latest``): at 1 kHz the HandStates
        were most of the reader's time (test_state_blocks_fast_path_equals_the_general)."""
        run: list[Telemetry] = []
        for item in items:
            if isinstance(item.message, m.State):
                run.append(item)
                continue
            self._take_run(run)
            run = []
            self._take_other(item)
        self._take_run(run)

    def _take_run(self, run: list[Telemetry]) -> None:
        if not run:
            return
        if self._state_callbacks or self._log is not None:
            states = [self._take_state(item) for item in run]
            if self._block_callbacks:
                self._dispatch(self._block_callbacks, StateBlock.of_states(states))
            return
        msgs = [cast(m.State, item.message) for item in run]
        host_time = self._session.clock.timestamp()
        with self._lock:
            unwrap = self._board_clock.unwrap
            board_time = [unwrap(msg.board_time, host_time) for msg in msgs]
            last = HandState.from_message(
                msgs[-1],
                self._fingers,
                self._status,
                self._tips,
                board_time=board_time[-1],
                host_time=host_time,
                seq=run[-1].seq,
            )
            self._latest = last
        if self._block_callbacks:
            block = StateBlock.of_messages(msgs, board_time, host_time, last)
            self._dispatch(self._block_callbacks, block)

    def _take_state(self, item: Telemetry) -> HandState:
        """One state sample as a HandState, to the log and the ``on_state`` callbacks."""
        host_time = self._session.clock.timestamp()
        with self._lock:
            st = self._state_of(cast(m.State, item.message), host_time, item.seq)
            self._latest = st
            log_ = self._log
        if log_ is not None:
            try:
                log_.write(st)
            except (OSError, ValueError) as exc:
                log.error("utrf hand: telemetry log %s failed: %s", log_.path, exc)
        self._dispatch(self._state_callbacks, st)
        return st

    def _take_other(self, item: Telemetry) -> None:
        """A status, fault or boot."""
        msg = item.message
        host_time = self._session.clock.timestamp()
        if isinstance(msg, m.Status):
            self._take_status(msg)
        elif isinstance(msg, m.Fault):
            with self._lock:
                event = FaultEvent(
                    finger=self._fingers[msg.finger],
                    index=msg.finger,
                    new_faults=msg.new_faults,
                    faults={n: msg.faults[i] for i, n in enumerate(self._fingers)},
                    board_time=self._fault_clock.unwrap(msg.board_time, host_time),
                    host_time=host_time,
                )
                self._faults_seen.append(event)
            self._dispatch(self._fault_callbacks, event)
        elif isinstance(msg, m.Boot):
            with self._lock:
                self._board_clock.restart()
                self._fault_clock.restart()
                self._status = None
                self._latest = None
            self._session.board_booted(msg)

    # --- faults ---------------------------------------------------------------------------------

    def fault_count(self) -> int:
        """How many faults were seen: where :meth:`check_new_faults` starts."""
        with self._lock:
            return len(self._faults_seen)

    def check_new_faults(self, seen: int, idx: Sequence[int], during: str) -> None:
        """FingerFaultError if one of these fingers latched a fault since ``seen``, the
        board's reset if it reset."""
        self._session.check_alive()
        with self._lock:
            new = [e for e in self._faults_seen[seen:] if e.index in idx]
        if new:
            raise FingerFaultError({e.finger: int(e.faults[e.finger]) for e in new}, during)

    def fault_error(self, exc: NackError, during: str) -> FingerFaultError:
        """The board's FAULTED nack as a FingerFaultError naming every faulted finger."""
        f = exc.detail if exc.detail < len(self._fingers) else None
        try:
            st = self.state()
            faults = {x.name: int(x.faults) for x in st if x.faults}
        except ProtocolError:
            faults = {}
        if f is not None and self._fingers[f] not in faults:
            faults[self._fingers[f]] = 0
        return FingerFaultError(faults, during)
