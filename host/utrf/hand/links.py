"""What the Hand needs of its link, opening one on a URL, and the callback that keeps the
frames a link reads before its Hand exists."""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import Protocol, TypeVar

from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.link import Link, LinkStats, Telemetry

R = TypeVar("R", bound=Message)


class LinkLike(Protocol):
    """What the Hand needs of its link: :class:`~utrf.protocol.link.Link` or a SimLink."""

    @property
    def identity(self) -> m.Identity | None: ...

    def request(
        self, msg: Request[R], *, timeout_s: float | None = None, retries: int | None = None
    ) -> R: ...

    def handshake(self, timeout_s: float = 3.0) -> m.Identity: ...

    heartbeat_period_s: float | None  # None stops the heartbeats (before a goodbye)

    def stats(self) -> LinkStats: ...

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None: ...

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None: ...

    def close(self) -> None: ...


class TelemetryForward:
    """A telemetry callback that exists before its Hand does: the link is built (and starts
    reading) first, so frames that arrive meanwhile (a ``boot``) are kept and handed over.
    A Link gives it each read's frames together (:meth:`batch`); a SimLink one at a time."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._target: Callable[[Sequence[Telemetry]], None] | None = None
        self._early: list[Telemetry] = []

    def __call__(self, item: Telemetry) -> None:
        self.batch((item,))

    def batch(self, items: Sequence[Telemetry]) -> None:
        with self._lock:
            target = self._target
            if target is None:
                self._early.extend(items)
                return
        target(items)

    def attach(self, target: Callable[[Sequence[Telemetry]], None]) -> None:
        with self._lock:
            early, self._early = self._early, []
            self._target = target
        if early:
            target(early)


def open_link(url: str, baudrate: int, forward: TelemetryForward, reset: bool) -> Link:
    """A Link on ``url``; the board reset by the open or not (``serial_port.open_line``)."""
    from utrf.hand.serial_port import open_line
    from utrf.protocol.transport import SerialTransport

    def opener() -> Link:
        # No queue: the Hand takes every frame through its callback (a queue nobody read
        # counted each frame as "dropped"); real loss is stream_lost.
        return Link(
            SerialTransport(url, baudrate), on_telemetry_batch=forward.batch, telemetry_queue_size=0
        )

    return open_line(url, reset, opener)
