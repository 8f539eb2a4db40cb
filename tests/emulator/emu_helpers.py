"""Helpers for the emulator's tests: a console for the fixture program's command line."""

from __future__ import annotations

from utrf.emulator import EmulatedBoard, SimSerial


class Console:
    """The fixture's ASCII command line, over a driven board's SimSerial."""

    def __init__(self, board: EmulatedBoard, timeout: float = 0.05) -> None:
        self.board = board
        self.port: SimSerial = board.serial(timeout=timeout)

    def line(self, timeout: float | None = None) -> str:
        if timeout is not None:
            self.port.timeout = timeout
        data = self.port.read_until(b"\n")
        if not data.endswith(b"\n"):
            raise TimeoutError(f"no line within {self.port.timeout} s (got {data!r})")
        return data.decode().strip()

    def command(self, text: str, timeout: float = 0.05) -> str:
        self.port.write(text.encode() + b"\n")
        return self.line(timeout)
