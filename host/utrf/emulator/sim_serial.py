"""A pyserial-like port into a driven emulated board, whose timeouts are simulated seconds."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from utrf.emulator._native import F_CPU_HZ
from utrf.emulator.board_types import EmulatorError

if TYPE_CHECKING:
    from utrf.emulator.board import EmulatedBoard


class SimSerial:
    """A pyserial-like port into a driven :class:`EmulatedBoard`: ``read`` runs the simulation
    until the bytes arrive or ``timeout`` *simulated* seconds pass (None: no limit).

    Implements what a protocol client uses: ``read``, ``read_until``, ``write``, ``flush``,
    ``in_waiting``, ``reset_input_buffer``, ``timeout``, ``is_open``, ``close``."""

    def __init__(self, board: EmulatedBoard, timeout: float | None = 1.0) -> None:
        self.board = board
        self.timeout = timeout
        self._buffer = bytearray()
        self.is_open = True

    def _pull(self) -> None:
        self._buffer += self.board.read()

    def _run_until(self, done: Callable[[], bool]) -> None:
        """Run one exchange period at a time (the finest step the board has) until done or
        the deadline. Within half a cycle of it counts as there: when time lands on the
        deadline, float rounding can leave a sliver no exchange runs, and the read would spin."""
        deadline = math.inf if self.timeout is None else self.board.sim_time + self.timeout
        step = self.board.exchange_period
        self._pull()
        while not done() and deadline - self.board.sim_time > 0.5 / F_CPU_HZ:
            self.board.run_for(step)
            self._pull()

    def read(self, size: int = 1) -> bytes:
        self._check_open()
        self._run_until(lambda: len(self._buffer) >= size)
        out = bytes(self._buffer[:size])
        del self._buffer[:size]
        return out

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        self._check_open()

        def found() -> bool:
            return expected in self._buffer or (size is not None and len(self._buffer) >= size)

        self._run_until(found)
        i = self._buffer.find(expected)
        end = len(self._buffer) if i < 0 else i + len(expected)
        if size is not None:
            end = min(end, size)
        out = bytes(self._buffer[:end])
        del self._buffer[:end]
        return out

    def write(self, data: bytes) -> int:
        self._check_open()
        return self.board.write(bytes(data))

    def flush(self) -> None:
        """Run until every byte written has gone out on the wire."""
        self._check_open()
        while self.board.uart_pending:
            self.board.run_for(1e-3)

    @property
    def in_waiting(self) -> int:
        self._pull()
        return len(self._buffer)

    def reset_input_buffer(self) -> None:
        self._pull()
        self._buffer.clear()

    def reset_output_buffer(self) -> None:
        """Bytes already queued are on the wire; nothing to drop."""

    def close(self) -> None:
        self.is_open = False

    def _check_open(self) -> None:
        if not self.is_open:
            raise EmulatorError("the port is closed")

    def __enter__(self) -> SimSerial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
