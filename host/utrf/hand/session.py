"""The Hand's session with one board: the link (replaced when the line is reopened), the
requests sent on it, and what is known of the board at its other end: its identity, its last
``boot``, whether it reset since the handshake, whether the Hand was closed."""

from __future__ import annotations

import logging
import threading
from typing import Any, TypeVar

from utrf.hand.clock import Clock
from utrf.hand.links import LinkLike
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.errors import BoardResetError, DisconnectedError, ProtocolError
from utrf.protocol.link import Link

log = logging.getLogger("utrf.hand.client")  # one logger for every part, named as it always was

R = TypeVar("R", bound=Message)


class HandSession:
    """The link to one board and the board's liveness (a part of :class:`~utrf.hand.Hand`)."""

    def __init__(
        self, link: LinkLike, clock: Clock, *, url: str | None, baudrate: int = m.DEFAULT_BAUD
    ) -> None:
        self.link = link
        self.clock = clock
        self.url = url
        self.baudrate = baudrate
        self._lock = threading.Lock()  # a boot arrives on the link's reader thread
        self._reset: BoardResetError | None = None
        self._last_boot: m.Boot | None = None
        self._handshaken = False
        self._identity: m.Identity | None = None
        self.closed = False

    # --- requests -------------------------------------------------------------------------------

    def request(self, msg: Request[R], **kwargs: Any) -> R:
        if self.closed:
            raise DisconnectedError("the hand was closed")
        return self.link.request(msg, **kwargs)

    def check_alive(self) -> None:
        """Raise what the next request would: a reset noticed from telemetry."""
        with self._lock:
            reset = self._reset if self._handshaken else None
        if reset is not None:
            raise reset

    # --- the board at the other end -------------------------------------------------------------

    @property
    def identity(self) -> m.Identity:
        if self._identity is None:
            raise ProtocolError("no handshake yet")
        return self._identity

    @property
    def last_boot(self) -> m.Boot | None:
        with self._lock:
            return self._last_boot

    @property
    def reset_seen(self) -> bool:
        """A ``boot`` came since the last handshake began: nothing can be sent."""
        with self._lock:
            return self._reset is not None

    @property
    def live(self) -> bool:
        """Handshaken and not reset since: the board takes commands."""
        with self._lock:
            return self._handshaken and self._reset is None

    def board_booted(self, msg: m.Boot) -> None:
        """The board reset (its ``boot``): every request from now raises until a handshake."""
        with self._lock:
            self._last_boot = msg
            self._reset = BoardResetError(msg)

    def handshake_begins(self) -> None:
        with self._lock:
            self._reset = None

    def identify(self, identity: m.Identity) -> None:
        """The handshake's answer: which board this is."""
        self._identity = identity

    def handshaken(self) -> None:
        """Set-up done: a reset from now makes every request raise."""
        with self._lock:
            self._handshaken = True

    def replace_link(self, link: LinkLike) -> None:
        """A new link on the same line (reopened): no handshake on it yet. It reads as the old
        one did (its linger, which a consumer such as the dashboard chose, is kept)."""
        old = self.link
        if isinstance(old, Link) and isinstance(link, Link):
            link.read_linger_s = old.read_linger_s
        self.link = link
        with self._lock:
            self._reset = None
            self._handshaken = False
