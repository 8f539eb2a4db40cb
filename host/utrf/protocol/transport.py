"""A byte pipe to the board over any pyserial URL, with a reader thread.

``/dev/ttyACM0`` (the MEGA's USB serial), ``socket://127.0.0.1:PORT`` (the emulated board),
``loop://`` (a loopback, for tests). The reader hands every chunk of bytes to a callback as
soon as it arrives and reports once, through another callback, when the line goes away.
"""

from __future__ import annotations

import errno
import os
import select
import threading
from collections.abc import Callable
from typing import Protocol

import serial

from utrf.protocol.errors import DisconnectedError, PortBusyError
from utrf.protocol.messages import DEFAULT_BAUD

DataCallback = Callable[[bytes], None]
CloseCallback = Callable[[BaseException | None], None]


class Transport(Protocol):
    """What :class:`~utrf.protocol.link.Link` needs from a line to the board."""

    def start(self, on_data: DataCallback, on_close: CloseCallback) -> None:
        """Start delivering received bytes to ``on_data``; ``on_close`` once at the end."""

    def write(self, data: bytes) -> None:
        """Send all of ``data``; DisconnectedError if the line is gone."""

    def close(self) -> None:
        """Stop the reader and release the line (idempotent)."""


class SerialTransport:
    """:class:`Transport` over ``serial.serial_for_url``."""

    #: how often the reader wakes to notice close() when nothing arrives
    POLL_S = 0.05

    def __init__(self, url: str, baudrate: int = DEFAULT_BAUD, **serial_kwargs: object) -> None:
        if "://" not in url and os.name == "posix":
            # One program at a time on a serial port (an advisory lock, as other tools take).
            serial_kwargs.setdefault("exclusive", True)
        try:
            self._serial = self._open(url, baudrate, serial_kwargs)
        except (serial.SerialException, ValueError) as exc:
            if getattr(exc, "errno", None) in (errno.EBUSY, errno.EAGAIN) or "lock" in str(exc):
                raise PortBusyError(
                    f"{url} is in use by another program (the OS says: {exc})"
                ) from exc
            raise DisconnectedError(f"cannot open {url!r}: {exc}") from exc
        self.url = url
        self._write_lock = threading.Lock()
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        try:
            self._fd: int | None = self._serial.fileno()
        except (AttributeError, NotImplementedError, OSError, serial.SerialException):
            self._fd = None  # loop:// and friends: poll instead of select

    @staticmethod
    def _open(url: str, baudrate: int, kwargs: dict[str, object]) -> serial.SerialBase:
        port = serial.serial_for_url(url, baudrate=baudrate, timeout=0, do_not_open=True, **kwargs)
        if url.startswith("socket://"):
            # A new connection holds no stale bytes, but pyserial's open() reads and drops
            # whatever came at once: a server's first words (why it refuses us) with it.
            port.reset_input_buffer = lambda: None
        port.open()
        return port

    def start(self, on_data: DataCallback, on_close: CloseCallback) -> None:
        if self._thread is not None:
            raise RuntimeError("transport already started")
        self._thread = threading.Thread(
            target=self._run, args=(on_data, on_close), name=f"utrf-rx {self.url}", daemon=True
        )
        self._thread.start()

    def _wait_readable(self) -> None:
        if self._fd is not None:
            select.select([self._fd], [], [], self.POLL_S)
        elif not self._serial.in_waiting:
            self._closing.wait(0.001)

    def _run(self, on_data: DataCallback, on_close: CloseCallback) -> None:
        error: BaseException | None = None
        try:
            while not self._closing.is_set():
                self._wait_readable()
                if self._closing.is_set():
                    break
                data = self._read()
                if data:
                    on_data(data)
        except (serial.SerialException, OSError, ValueError, TypeError) as exc:
            if not self._closing.is_set():
                error = exc
        finally:
            on_close(error)

    def _read(self) -> bytes:
        """Everything that has arrived, at once (non-blocking)."""
        sock = getattr(self._serial, "_socket", None)
        if sock is None:
            return bytes(self._serial.read(4096))
        # socket://: pyserial's read drops what it got when the peer then hangs up (a server
        # that says why it refuses and closes): take it from the (non-blocking) socket.
        try:
            data = sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return b""
        if not data:
            raise serial.SerialException("socket disconnected")
        return bytes(data)

    def write(self, data: bytes) -> None:
        with self._write_lock:
            if self._closing.is_set():
                raise DisconnectedError(f"{self.url}: the transport is closed")
            try:
                self._serial.write(data)
            except (serial.SerialException, OSError) as exc:
                raise DisconnectedError(f"{self.url}: write failed: {exc}") from exc

    def close(self) -> None:
        if self._closing.is_set():
            return
        self._closing.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        with self._write_lock:
            self._serial.close()
