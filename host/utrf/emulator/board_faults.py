"""Fault injection on the emulated board: the serial line (loss, corruption, noise, a dropped
client) and the MCU (slow or stalled interrupts, a stopped tick timer or ADC, a hung firmware).
A mixin of :class:`utrf.emulator.board.EmulatedBoard`; every method holds the board's lock."""

from __future__ import annotations

import math
import random
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any

from utrf.emulator import _native
from utrf.emulator._native import F_CPU_HZ
from utrf.emulator.board_types import VECTORS, EmulatorError

if TYPE_CHECKING:
    from utrf.emulator._native import NativeBoard

# Registers the board's faults touch (ATmega2560 datasheet, data-space addresses).
_TCCR2B, _CS2_MASK = 0xB1, 0x07
_ADCSRA, _ADEN, _ADSC = 0x7A, 0x80, 0x40

_CLI = 0x94F8  # cli
_RJMP_SELF = 0xCFFF  # rjmp . (to itself)


class BoardFaults:
    """The faults an :class:`~utrf.emulator.board.EmulatedBoard` can be given."""

    if TYPE_CHECKING:  # provided by EmulatedBoard
        _lock: AbstractContextManager[Any]
        _cycle: int
        seed: int

        def _board(self) -> NativeBoard: ...

    def drop_client(self) -> None:
        """Hang up on the TCP client, as a pulled USB cable would (it reads end-of-file)."""
        with self._lock:
            self._board().drop_client()

    def set_line_faults(
        self,
        direction: str = "both",
        *,
        drop: float = 0.0,
        corrupt: float = 0.0,
        insert: float = 0.0,
        duplicate: float = 0.0,
        burst: float = 0.0,
        burst_length: tuple[int, int] = (8, 32),
    ) -> None:
        """Serial line faults, as probabilities per byte, seeded (reproducible when driven):
        ``drop`` it, ``corrupt`` it (one bit flipped), ``insert`` a random byte before it,
        ``duplicate`` it (sent twice), or start a ``burst`` of noise there that replaces it and
        the bytes after it, ``burst_length`` = (min, max) bytes in all, uniformly. ``direction``:
        "to_board", "to_host", "both". All zero: a clean line. Counted in ``stats``
        (``rx_dropped``, ``tx_duplicated``, ``rx_burst_bytes``, ...)."""
        dirs: dict[str, tuple[int, ...]] = {
            "to_board": (_native.TO_BOARD,),
            "to_host": (_native.TO_HOST,),
        }
        dirs["both"] = dirs["to_board"] + dirs["to_host"]
        if direction not in dirs:
            raise EmulatorError(f"direction must be one of {list(dirs)}, got {direction!r}")
        probs = (
            ("drop", drop),
            ("corrupt", corrupt),
            ("insert", insert),
            ("duplicate", duplicate),
            ("burst", burst),
        )
        for name, p in probs:
            below_one = name in ("insert", "duplicate")
            if not (isinstance(p, int | float) and 0.0 <= p <= 1.0) or (below_one and p >= 1):
                bound = "[0, 1)" if below_one else "[0, 1]"
                raise EmulatorError(f"{name} must be a probability in {bound}, got {p!r}")
        try:
            lo, hi = (int(n) for n in burst_length)
        except (TypeError, ValueError):
            raise EmulatorError(
                f"burst_length must be (min, max) bytes, got {burst_length!r}"
            ) from None
        if not 1 <= lo <= hi <= 65536:
            raise EmulatorError(
                f"burst_length must be (min, max) with 1 <= min <= max, got {burst_length!r}"
            )
        with self._lock:
            for d in dirs[direction]:
                self._board().set_line_faults(
                    d, float(drop), float(corrupt), float(insert), float(duplicate),
                    float(burst), (lo, hi),
                )  # fmt: skip

    def inject_noise(self, data: bytes | int, direction: str = "to_board") -> None:
        """Put a burst of bytes on the line (an int: that many random bytes from the seed)."""
        if isinstance(data, int):
            if data < 0:
                raise EmulatorError(f"noise burst length must be >= 0, got {data}")
            # stdlib random: numpy.random loads lazily, a first load mid-soak looks like a leak
            data = random.Random(f"{self.seed}:{int(self._cycle)}").randbytes(data)
        d = {"to_board": _native.TO_BOARD, "to_host": _native.TO_HOST}.get(direction)
        if d is None:
            raise EmulatorError(f"direction must be 'to_board' or 'to_host', got {direction!r}")
        with self._lock:
            self._board().inject(d, bytes(data))

    def slow_tick(self, extra_s: float, count: int | None = 1) -> None:
        """A slow control tick: each of the next ``count`` timer-2 compare interrupts (the 1 kHz
        tick; None: every one until called again with 0) takes ``extra_s`` seconds longer, as
        if the handler ran that many more cycles (the timers run on meanwhile). Past one tick
        period (1 ms) the next compare comes before the tick ends: the firmware latches
        OVERRUN. ``extra_s`` 0 or ``count`` 0 ends it. ``stats["stalls"]`` counts the slow
        ticks."""
        self.stall_interrupt("TIMER2_COMPA", extra_s, count)

    def stall_interrupt(self, vector: int | str, extra_s: float, count: int | None = 1) -> None:
        """Make ``count`` entries of an interrupt handler (name as in :data:`VECTORS` or number;
        None: every entry) last ``extra_s`` seconds longer. See :meth:`slow_tick`."""
        if isinstance(vector, str):
            if vector not in VECTORS:
                raise EmulatorError(f"unknown vector {vector!r}; known: {sorted(VECTORS)}")
            vector = VECTORS[vector]
        if not (isinstance(extra_s, int | float) and math.isfinite(extra_s) and 0 <= extra_s <= 10):
            raise EmulatorError(f"extra_s must be a duration in [0, 10] s, got {extra_s!r}")
        if count is not None and (
            isinstance(count, bool) or not isinstance(count, int) or count < 0
        ):
            raise EmulatorError(f"count must be an int >= 0 or None (every entry), got {count!r}")
        cycles = round(extra_s * F_CPU_HZ)
        with self._lock:
            self._board().stall_vector(int(vector), cycles, -1 if count is None else count)

    @property
    def slow_ticks_left(self) -> int | None:
        """Slow ticks still to come (None: every tick is slow; 0: none)."""
        with self._lock:
            left = self._board().stalls_left()
        return None if left < 0 else left

    def stop_tick_timer(self) -> None:
        """The tick's timer stops: timer 2's clock select is cleared (TCCR2B's CS22..CS20, as a
        glitch on the register would), so no compare interrupt comes; everything else runs,
        ``loop()`` included, which finds no tick for 20 ms (the tick-alive rule: every motor
        off, the watchdog resets the board). The firmware's own set-up after the reset
        starts the timer again; nothing else does."""
        with self._lock:
            board = self._board()
            tccr2b = board.read_data(_TCCR2B, 1)[0]
            board.write_io(_TCCR2B, tccr2b & ~_CS2_MASK)

    def stop_adc(self) -> None:
        """The ADC stops: ADEN is cleared under the conversion in progress, which then never
        completes; the firmware's sampling round waits for it, the encoder readings go stale
        (after 3 ticks: ENCODER_RANGE on every finger, motors off). It stays stopped until
        :meth:`restart_adc` or a reset (the firmware enables the ADC at start)."""
        with self._lock:
            board = self._board()
            adcsra = board.read_data(_ADCSRA, 1)[0]
            board.poke(_ADCSRA, adcsra & ~_ADEN)

    def restart_adc(self) -> None:
        """Undo :meth:`stop_adc`: enable the ADC and redo the conversion it lost, so the
        firmware's round goes on."""
        with self._lock:
            board = self._board()
            adcsra = board.read_data(_ADCSRA, 1)[0]
            if adcsra & _ADEN:
                return
            board.poke(_ADCSRA, (adcsra | _ADEN) & ~_ADSC)
            board.write_io(_ADCSRA, adcsra | _ADEN | _ADSC)

    def hang_firmware(self, interrupts: bool = True) -> None:
        """Hang the firmware in a self-loop, as a bug that never returns would. With
        ``interrupts`` on, ``loop()`` hangs at its next start (no lock held, no interrupt
        under way) and the timer interrupts go on, so the firmware's own tick sees ``loop()``
        stop; off, the CPU stops where it stands with interrupts disabled. Either way only the
        watchdog gets the board back. The self-loop is libgcc's ``_exit``: ``cli``, then
        ``__stop_program: rjmp .``."""
        with self._lock:
            board = self._board()
            exit_, loop = board.symbol("_exit"), board.symbol("loop")
            if exit_ is None or (interrupts and loop is None):
                raise EmulatorError("the ELF lacks the _exit or loop symbol to hang it with")
            words = (board.flash_word(exit_), board.flash_word(exit_ + 2))
            if words != (_CLI, _RJMP_SELF):
                raise EmulatorError(
                    f"_exit at {exit_:#x} is not 'cli; rjmp .' (words {words[0]:#06x} "
                    f"{words[1]:#06x})"
                )
            if interrupts and loop is not None:  # (loop is known when interrupts: see above)
                done = board.jump_at(loop, exit_ + 2, 1)
            else:
                done = board.jump(exit_, -1)
            if not done:
                raise EmulatorError(f"_exit at {exit_:#x} or loop is not a flash address")
