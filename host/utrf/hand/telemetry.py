"""What the board reports: the state stream, faults, the board's reset, the telemetry log,
and the freshest state a wait can use."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from utrf.hand.errors import FingerFaultError
from utrf.hand.session import HandSession, log
from utrf.hand.state import FaultEvent, HandState
from utrf.hand.telemetry_log import TelemetryLog
from utrf.protocol import messages as m
from utrf.protocol.errors import BoardResetError, NackError, ProtocolError
from utrf.protocol.link import Telemetry


class HandTelemetry(HandSession):
    """The Hand's view of what its board reports (a part of :class:`~utrf.hand.Hand`)."""

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
        msg = self._request(m.GetState())
        with self._lock:
            status = self._status
        if status is None or status.change != msg.status_seq:
            self._take_status(self._request(m.GetStatus()))
        host_time = self.clock.timestamp()
        with self._lock:
            st = self._state_of(msg, host_time)
            if self._latest is None or st.board_time >= self._latest.board_time:
                self._latest = st
        return st

    def _poll_period(self) -> float:
        """How often a wait looks at the state: each sample at the stream's rate, between
        2 ms and 20 ms (20 ms without a stream: each look is then a get_state)."""
        period = 1.0 / self._telemetry_hz if self._telemetry_hz else 0.02
        return min(max(period, 0.002), 0.02)

    def _fresh_state(self, previous: HandState | None) -> HandState:
        """The latest telemetry sample if it is newer than ``previous`` and recent; else ask."""
        self._check_alive()
        st = self.latest
        if (
            st is not None
            and self._telemetry_hz
            and (previous is None or st.board_time > previous.board_time)
            and self.clock.timestamp() - st.host_time < max(5.0 / self._telemetry_hz, 0.1)
        ):
            return st
        return self.state()

    # --- the stream -----------------------------------------------------------------------------

    def set_telemetry(self, rate_hz: int) -> None:
        """Stream the hand's state at ``rate_hz`` (0 stops; at most 500 Hz)."""
        if not 0 <= rate_hz <= m.MAX_TELEMETRY_HZ:
            raise ValueError(f"rate_hz must lie in 0..{m.MAX_TELEMETRY_HZ}, got {rate_hz}")
        self._request(m.SetTelemetry(rate_hz=int(rate_hz)))
        self._telemetry_hz = int(rate_hz)

    def on_state(self, callback: Callable[[HandState], None]) -> Callable[[], None]:
        """Call ``callback(HandState)`` for every telemetry sample (from the link's reader
        thread on a real link: keep it short). Returns a function that unsubscribes; once it
        returns, the callback is not called again."""
        return self._subscribe(self._state_callbacks, callback)

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

    def on_fault(self, callback: Callable[[FaultEvent], None]) -> Callable[[], None]:
        """Call ``callback(FaultEvent)`` whenever a finger latches a fault. Returns a function
        that unsubscribes."""
        return self._subscribe(self._fault_callbacks, callback)

    def start_log(self, path: str | Path) -> TelemetryLog:
        """Log every telemetry sample to a CSV file (appended when its columns match)."""
        log_ = TelemetryLog(path, self.fingers)
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
            self.fingers,
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

    def _on_telemetry(self, item: Telemetry) -> None:
        msg = item.message
        host_time = self.clock.timestamp()
        if isinstance(msg, m.Status):
            self._take_status(msg)
        elif isinstance(msg, m.State):
            with self._lock:
                st = self._state_of(msg, host_time, item.seq)
                self._latest = st
                log_ = self._log
            if log_ is not None:
                try:
                    log_.write(st)
                except (OSError, ValueError) as exc:
                    log.error("utrf hand: telemetry log %s failed: %s", log_.path, exc)
            self._dispatch(self._state_callbacks, st)
        elif isinstance(msg, m.Fault):
            with self._lock:
                event = FaultEvent(
                    finger=self.fingers[msg.finger],
                    index=msg.finger,
                    new_faults=msg.new_faults,
                    faults={n: msg.faults[i] for i, n in enumerate(self.fingers)},
                    board_time=self._fault_clock.unwrap(msg.board_time, host_time),
                    host_time=host_time,
                )
                self._faults_seen.append(event)
            self._dispatch(self._fault_callbacks, event)
        elif isinstance(msg, m.Boot):
            with self._lock:
                self._last_boot = msg
                self._board_clock.restart()
                self._fault_clock.restart()
                self._status = None
                self._reset = BoardResetError(msg)
                self._latest = None

    # --- faults ---------------------------------------------------------------------------------

    def _check_new_faults(self, seen: int, idx: Sequence[int], during: str) -> None:
        self._check_alive()
        with self._lock:
            new = [e for e in self._faults_seen[seen:] if e.index in idx]
        if new:
            raise FingerFaultError({e.finger: int(e.faults[e.finger]) for e in new}, during)

    def _fault_error(self, exc: NackError, during: str) -> FingerFaultError:
        f = exc.detail if exc.detail < len(self.fingers) else None
        try:
            st = self.state()
            faults = {x.name: int(x.faults) for x in st if x.faults}
        except ProtocolError:
            faults = {}
        if f is not None and self.fingers[f] not in faults:
            faults[self.fingers[f]] = 0
        return FingerFaultError(faults, during)
