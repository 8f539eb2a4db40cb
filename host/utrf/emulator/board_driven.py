"""The driven board's time (``realtime=False``): the lockstep with the plant run in C, up to a
time, between a predicate's looks, or from one frame the board sends to the next. A mixin of
:class:`utrf.emulator.board.EmulatedBoard`; its public callers hold the board's lock."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from utrf.emulator._native import F_CPU_HZ
from utrf.emulator.board_types import EmulatorError

if TYPE_CHECKING:
    from utrf.emulator._native import NativeBoard


#: a run ahead's heartbeats (:meth:`BoardDriven.run_ahead_stops`): ``(seq, frame)`` each, the
#: next due (s), the period (s), the seqs whose acks count, the message kinds (256 bytes)
Beats = tuple[list[tuple[int, bytes]], float, float, set[int], bytes]


@dataclass(frozen=True)
class AheadRun:
    """What a run ahead (:meth:`BoardDriven.run_ahead`) did: ``marks``, each period's end in
    which a frame ended (the output's bytes up to it, not yet read; simulated s there), where
    a client stopping at every frame would have looked; ``sent_at``: when the bytes that
    waited went (s; None: not yet); ``done``: whether it reached its end (a crash, or marks
    full, end it early)."""

    marks: list[tuple[int, float]]
    sent_at: float | None
    done: bool


class BoardDriven:
    """Simulated time as a driven :class:`~utrf.emulator.board.EmulatedBoard` moves it."""

    if TYPE_CHECKING:  # provided by EmulatedBoard
        _lock: AbstractContextManager[Any]
        _native: NativeBoard
        _cycle: int
        _period_cycles: int
        _status: int
        _busy: float
        _driven_wall: float
        _capture: bool
        _ahead: int | None
        realtime: bool
        crash_pc: int | None

        def _board(self) -> NativeBoard: ...

    def _run_plant(self, target: int, wake: int = -1) -> None:
        """Run in lockstep with the plant up to cycle ``target``, all in C: each exchange
        period the MCU runs with the encoders as the plant had them at its start, then the
        plant runs the same period with the pins as the MCU had set them at its start.
        ``wake`` (a byte value): stop early after the period in which the board sent it."""
        if wake < 0:
            status = self._native.run_plant(target, self._period_cycles)
        else:
            status = self._native.run_plant_until(target, self._period_cycles, wake)
        self._cycle = self._native.cycle
        if status != self._status:
            self._status = status
            self.crash_pc = self._native.pc if status == 1 else None

    def _exchanges_on(self, n: int) -> int:
        """The cycle ``n`` exchange periods on: the plant steps whole periods on its own clock,
        which the MCU's overshoot (a few cycles past each period's end) does not move."""
        return self._native.plant_cycle + n * self._period_cycles

    def _exchange(self) -> None:
        """One lockstep period."""
        self._run_plant(self._exchanges_on(1))

    def _run_driven(self, seconds: float, until: Callable[[Any], bool] | None = None) -> bool:
        target = self._cycle + round(seconds * F_CPU_HZ)
        with self._timed():
            if until is None:
                while self._cycle < target:  # one call; again only if a crash stopped it
                    self._run_plant(target)
                return False
            while self._cycle < target:  # the predicate is judged between exchanges
                self._exchange()
                if until(self):
                    return True
            return False

    @contextmanager
    def _timed(self) -> Iterator[None]:
        """Count the wall time of a driven run as busy (the board's real-time figures)."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            dt = time.perf_counter() - t0
            self._busy += dt
            self._driven_wall += dt

    def run_until_output(
        self, seconds: float, until: Callable[[], bool] | None = None, byte: int = 0
    ) -> bool:
        """Driven: run ``seconds`` of simulated time in whole exchanges (the last one may pass
        it), stopping after each exchange in which the board sent ``byte`` (0x00 by default,
        the end of every protocol frame) to the captured output, where ``until()`` says whether
        to end there (None: end at the first). In C between those stops however long the
        wait: a client looks at the output when a frame has come, not at every exchange (as
        ``run_until`` does). Returns whether it ended early."""
        if self.realtime:
            raise EmulatorError("run_until_output needs realtime=False; in real time read the port")
        if not (isinstance(seconds, int | float) and math.isfinite(seconds) and seconds >= 0):
            raise EmulatorError(f"seconds must be a finite number >= 0, got {seconds!r}")
        if not (isinstance(byte, int) and 0 <= byte <= 255):
            raise EmulatorError(f"byte must be 0..255, got {byte!r}")
        if not self._capture:
            raise EmulatorError("run_until_output needs capture=True")
        with self._lock:
            self._board()
            target = self._exchanges_on(-(-round(seconds * F_CPU_HZ) // self._period_cycles))
            with self._timed():
                while self._cycle < target:
                    self._run_plant(target, byte)
                    if self._cycle < target and (until is None or until()):
                        return True
                return False

    def exchanges_end(self, seconds: float) -> float:
        """Where a driven run of ``seconds`` (:meth:`run_until_output`, :meth:`run_ahead`)
        ends on the plant's clock, in s: whole exchange periods (the MCU ends a few cycles
        past it)."""
        return self._exchanges_end(seconds) / F_CPU_HZ

    def _exchanges_end(self, seconds: float) -> int:
        return self._exchanges_on(-(-round(seconds * F_CPU_HZ) // self._period_cycles))

    def exchanges_after(self, plant_cycle: int, seconds: float) -> int:
        """The cycle a run of ``seconds`` from a stop at ``plant_cycle`` (the plant's clock)
        ends at, as :meth:`exchanges_end` computes it from there: a run ahead's later stops."""
        return plant_cycle + -(-round(seconds * F_CPU_HZ) // self._period_cycles) * (
            self._period_cycles
        )

    @property
    def plant_cycle(self) -> int:
        """The plant's clock (cycles): where the next exchange starts."""
        return int(self._native.plant_cycle)

    def run_ahead_stops(
        self,
        targets: list[int],
        t0: float,
        hits: list[tuple[float, int, int, Any, float]],
        beats: Beats | None = None,
    ) -> None:
        """:meth:`run_ahead` through stops at ``targets`` (cycles, rising; each where a run
        ahead to it would end, the last the run's end): at each the hits due are applied
        (``(at, body, site, world impulse, duration)``, due once ``cycle / F_CPU_HZ - t0``
        reaches ``at``) and the plant's truth recorded (:meth:`run_ahead_stops_done`).
        ``beats``: the heartbeats the harness sends at the client's times (``(seq, frame)``
        each, the next due, the period, the seqs whose acks count, the message kinds:
        ``utrf_sim_ahead_beats``; :meth:`run_ahead_beats_done`)."""
        if self.realtime or not self._capture:
            raise EmulatorError("run_ahead needs realtime=False and capture=True")
        if not targets:
            raise EmulatorError("a run ahead with stops needs at least one")
        self._lock.__enter__()  # held until the join: no other thread touches the board
        try:
            native = self._board()
            native.ahead_stops(targets, t0, hits)
            if beats is not None:
                native.ahead_beats(*beats)
            native.ahead_start(targets[-1], self._period_cycles, 0)
        except BaseException:
            self._lock.__exit__(None, None, None)
            raise
        self._ahead = targets[-1]
        self._ahead_t0 = time.perf_counter()

    def run_ahead_stops_done(self) -> tuple[list[int], Any, list[int]]:
        """After the join: the stops reached (the MCU's cycles), their truths (n, 32: the tip
        sites' world positions (15), the motors' currents (10)) and each hit's stop (-1: not
        applied)."""
        return self._native.ahead_stops_done()

    def run_ahead_beats_done(self) -> tuple[list[int], list[float]]:
        """After the join: the heartbeats the harness sent (their cycles) and the due times
        they went for."""
        return self._native.ahead_beats_done()

    def run_ahead_beats_next(self) -> tuple[float, set[int]] | None:
        """After the join: where the harness's heartbeat rule stands (the next due time, the
        seqs whose acks still count; None: off or frozen), before the client has taken the
        run's frames."""
        return self._native.ahead_beats_next()

    def run_ahead(self, seconds: float, send: tuple[bytes, float] | None = None) -> None:
        """Driven: start running ``seconds`` of simulated time in whole exchanges (the same
        end as :meth:`run_until_output`'s) on the harness's own thread, and return at once:
        the caller works meanwhile, on anything but this board, until :meth:`run_ahead_join`.
        The run is :meth:`run_until_output`'s to the cycle; the exchanges in which a frame
        ended are marked instead of stopped at. ``send``: (bytes, time): written to UART0 at
        the first exchange's end at or past ``time`` (s) within the run (a heartbeat)."""
        if self.realtime or not self._capture:
            raise EmulatorError("run_ahead needs realtime=False and capture=True")
        if not (isinstance(seconds, int | float) and math.isfinite(seconds) and seconds >= 0):
            raise EmulatorError(f"seconds must be a finite number >= 0, got {seconds!r}")
        self._lock.__enter__()  # held until the join: no other thread touches the board
        try:
            native = self._board()
            target = self._exchanges_end(seconds)
            if send is not None:
                native.ahead_send(send[0], send[1])
            native.ahead_start(target, self._period_cycles, 0)
        except BaseException:
            self._lock.__exit__(None, None, None)
            raise
        self._ahead = target
        self._ahead_t0 = time.perf_counter()

    def run_ahead_join(self) -> AheadRun:
        """Wait for the run :meth:`run_ahead` started; what it did."""
        target = self._ahead
        if target is None:
            raise EmulatorError("no run ahead to join")
        native = self._native
        try:
            status = native.ahead_join()
        finally:
            self._ahead = None
            dt = time.perf_counter() - self._ahead_t0
            self._busy += dt
            self._driven_wall += dt
            self._lock.__exit__(None, None, None)
        self._cycle = native.cycle
        if status != self._status:
            self._status = status
            self.crash_pc = native.pc if status == 1 else None
        offsets, cycles = native.ahead_marks()
        sent, _taken = native.ahead_sent()
        return AheadRun(
            [(n, c / F_CPU_HZ) for n, c in zip(offsets, cycles, strict=True)],
            sent / F_CPU_HZ if sent else None,
            self._cycle >= target,
        )
