"""What the emulated board shows of the MCU: the driver pins and ADC inputs, the harness's
counters and log, the reset flags, cycle profiles of an interrupt or a function, ELF symbols
and the data space. A mixin of :class:`utrf.emulator.board.EmulatedBoard`; every method holds
the board's lock."""

from __future__ import annotations

from contextlib import AbstractContextManager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from utrf.emulator.board_types import RESET_FLAGS, VECTORS, CycleProfile, EmulatorError, PinState

if TYPE_CHECKING:
    from utrf.emulator._native import NativeBoard


class BoardProbes:
    """The MCU as an :class:`~utrf.emulator.board.EmulatedBoard` lets a test look into it."""

    if TYPE_CHECKING:  # provided by EmulatedBoard
        _lock: AbstractContextManager[Any]
        elf: Path

        def _board(self) -> NativeBoard: ...

    @property
    def pins(self) -> PinState:
        """The driver inputs as the firmware has set them, now."""
        with self._lock:
            return PinState.from_block(self._board().pins)

    @property
    def adc_volts(self) -> np.ndarray:
        """The voltages on ADC0..4 (the encoders' outputs) as the firmware samples them now."""
        with self._lock:
            return self._board().adc_volts[:5].copy()

    @property
    def stats(self) -> dict[str, int]:
        """Harness counters (bytes each way, line faults, resets, clients, EEPROM writes...)."""
        with self._lock:
            return self._board().stats()

    def rx_timing(self, clear: bool = False) -> dict[str, int]:
        """The receive path as the chip's receiver sees it, since the last clear: bytes read,
        their worst wait from the end of the stop bit to the read of UDR0 (cycles), bytes
        lost to the two-byte FIFO (``overruns``) and frame errors."""
        with self._lock:
            return self._board().rx_timing(clear)

    @property
    def reset_flags(self) -> set[str]:
        """MCUSR's reset flags as the firmware finds them after the last reset."""
        flags = self.stats["last_reset_flags"]
        return {name for name, bit in RESET_FLAGS.items() if flags & bit}

    @property
    def reset_cause(self) -> str:
        """The highest-priority reset flag (the protocol's ResetCause order), or ``unknown``."""
        flags = self.reset_flags
        return next((name for name in RESET_FLAGS if name in flags), "unknown")

    @property
    def log(self) -> str:
        """simavr's recent errors and warnings for this board."""
        with self._lock:
            return self._board().log()

    def profile_interrupt(self, vector: int | str | None) -> None:
        """Start counting cycles in an interrupt handler (number or name, e.g. TIMER2_COMPA;
        None stops). Figures restart from zero."""
        if isinstance(vector, str):
            if vector not in VECTORS:
                raise EmulatorError(f"unknown vector {vector!r}; known: {sorted(VECTORS)}")
            vector = VECTORS[vector]
        with self._lock:
            self._board().profile_vector(0 if vector is None else int(vector))

    def profile_function(self, function: str | int | None) -> None:
        """Start counting cycles in a function (ELF symbol or byte address; None stops)."""
        with self._lock:
            if function is None:
                self._board().profile_function(-1)
                return
            addr = self.symbol(function) if isinstance(function, str) else int(function)
            if addr is None:
                raise EmulatorError(f"no symbol {function!r} in {self.elf}")
            self._board().profile_function(addr)

    def profile(self) -> dict[str, CycleProfile]:
        """The running profiles: ``interrupt`` and ``function``."""
        with self._lock:
            b = self._board()
            return {
                "interrupt": CycleProfile.from_native(b.profile(0)),
                "function": CycleProfile.from_native(b.profile(1)),
            }

    def symbol(self, name: str) -> int | None:
        """An ELF symbol's address (data symbols: SRAM address, without avr-gcc's 0x800000)."""
        with self._lock:
            addr = self._board().symbol(name)
        if addr is not None and addr >= 0x800000:
            addr -= 0x800000
        return addr

    def read_ram(self, address: int | str, size: int) -> bytes:
        """Bytes of the data space (registers and SRAM) at an address or a data symbol."""
        if isinstance(address, str):
            addr = self.symbol(address)
            if addr is None:
                raise EmulatorError(f"no symbol {address!r} in {self.elf}")
            address = addr
        with self._lock:
            return self._board().read_data(int(address), int(size))
