"""A byte pipe to the board over any pyserial URL, with a reader thread.

``/dev/ttyACM0`` (the MEGA's USB serial), ``socket://127.0.0.1:PORT`` (the emulated board),
``loop://`` (a loopback, for tests). The reader hands every chunk of bytes to a callback as
soon as it arrives and reports once, through another callback, when the line goes away.

A reader may *linger* (``linger_s``): after each read it waits that long before the next, so
one read carries many frames of a fast stream (each read and wake-up costs the host more than
decoding a frame: docs/dashboard.md); while a request waits for its reply
(:meth:`SerialTransport.awaiting_reply`) it never lingers, so a reply is read as soon as it
arrives, as without lingering. A consumer that wants the stream's newest now (a page about to
draw) asks with :meth:`SerialTransport.read_soon`: the linger under way ends, and the next read
is not lingered for, so the reader may linger long between such asks and read seldom.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import threading
from collections.abc import Callable, Iterator
from typing import Protocol

import serial

from utrf.protocol.errors import DisconnectedError, PortBusyError
from utrf.protocol.messages import DEFAULT_BAUD

DataCallback = Callable[[bytes], None]
CloseCallback = Callable[[BaseException | None], None]


class Transport(Protocol):
    """What :class:`~utrf.protocol.link.Link` needs from a line to the board."""

    linger_s: float  # the reader's wait after each read (see the module's text)

    def start(self, on_data: DataCallback, on_close: CloseCallback) -> None:
        """Start delivering received bytes to ``on_data``; ``on_close`` once at the end."""

    def write(self, data: bytes) -> None:
        """Send all of ``data``; DisconnectedError if the line is gone."""

    def close(self) -> None:
        """Stop the reader and release the line (idempotent)."""

    def awaiting_reply(self) -> contextlib.AbstractContextManager[None]:
        """Within it a request waits for its reply: received bytes are handed on at once."""

    def read_soon(self) -> None:
        """What has arrived and what arrives next is handed on at once (ends a linger)."""


class SerialTransport:
    """:class:`Transport` over ``serial.serial_for_url``."""

    #: how often the reader wakes to notice close() when nothing arrives
    POLL_S = 0.05

    def __init__(
        self,
        url: str,
        baudrate: int = DEFAULT_BAUD,
        *,
        linger_s: float = 0.0,
        **serial_kwargs: object,
    ) -> None:
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
        self.linger_s = linger_s
        self._awaited = 0  # requests waiting for a reply (no lingering while any does)
        self._awaited_lock = threading.Lock()
        self._hurry = threading.Event()  # ends a linger early (a request, read_soon, close)
        self._soon = False  # read_soon: the next read is not lingered for
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
                    self._soon = False  # this read answers it (one asked during on_data stays)
                    on_data(data)
                    self._linger()
        except (serial.SerialException, OSError, ValueError, TypeError) as exc:
            if not self._closing.is_set():
                error = exc
        finally:
            on_close(error)

    @property
    def linger_s(self) -> float:
        """Seconds the reader waits after a read before the next, unless a request awaits
        its reply (0: it reads whatever arrives at once)."""
        return self._linger_s

    @linger_s.setter
    def linger_s(self, value: float) -> None:
        if not 0.0 <= value <= 0.1:
            raise ValueError(f"linger_s must lie in 0..0.1 s, got {value}")
        self._linger_s = float(value)

    @contextlib.contextmanager
    def awaiting_reply(self) -> Iterator[None]:
        with self._awaited_lock:
            self._awaited += 1
        self._hurry.set()  # a linger under way ends now
        try:
            yield
        finally:
            with self._awaited_lock:
                self._awaited -= 1

    def read_soon(self) -> None:
        """Hand on what has arrived now and, if nothing has, what arrives next, without
        lingering: for a consumer that wants the stream's newest sample at once."""
        self._soon = True
        self._hurry.set()

    def _linger(self) -> None:
        """Wait ``linger_s`` before the next read, unless a request awaits its reply or
        :meth:`read_soon` asked (cleared first: one that comes after the check ends the wait
        at once)."""
        linger = self._linger_s
        if linger <= 0.0:
            return
        self._hurry.clear()
        if not self._awaited and not self._soon and not self._closing.is_set():
            self._hurry.wait(linger)

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
        self._hurry.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        with self._write_lock:
            self._serial.close()
