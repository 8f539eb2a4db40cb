"""Riding out the board's auto-reset, the handshake, closing in a safe mode, and reconnecting
after a reset or a lost line. (Building a Hand, ``Hand.connect`` and ``Hand.emulated``, is in
:mod:`utrf.hand.client`.)"""

from __future__ import annotations

from typing import Literal

from utrf.hand.configuration import HandConfiguration
from utrf.hand.control import HandControl
from utrf.hand.fingers import ALL_FINGERS, Fingers
from utrf.hand.goals import Goals
from utrf.hand.links import TelemetryForward, open_link
from utrf.hand.session import HandSession, log
from utrf.hand.telemetry import HandTelemetry
from utrf.protocol import messages as m
from utrf.protocol.errors import (
    BoardResetError,
    DisconnectedError,
    NackError,
    ProtocolError,
    ReplyTimeout,
)

OnClose = Literal["brake", "coast", "hold"]
ON_CLOSE = ("brake", "coast", "hold")


class HandLifecycle:
    """Handshaking, closing and reopening (a part of :class:`~utrf.hand.Hand`)."""

    def __init__(
        self,
        session: HandSession,
        fingers: Fingers,
        telemetry: HandTelemetry,
        control: HandControl,
        configuration: HandConfiguration,
        goals: Goals,
        *,
        on_close: OnClose = "brake",
        reset_on_open: bool = True,
    ) -> None:
        if on_close not in ON_CLOSE:
            raise ValueError(f"on_close must be one of {ON_CLOSE}, got {on_close!r}")
        self._session = session
        self._fingers = fingers
        self._telemetry = telemetry
        self._control = control
        self._configuration = configuration
        self._goals = goals
        self.on_close: OnClose = on_close
        self.reset_on_open = reset_on_open  # how reconnect() reopens the line

    # --- starting -------------------------------------------------------------------------------

    def start(self, boot_wait_s: float, handshake_timeout_s: float) -> None:
        """Wait up to ``boot_wait_s`` for the board's ``boot`` (its auto-reset), handshake."""
        clock = self._session.clock
        deadline = clock.now() + boot_wait_s
        while not self._session.reset_seen and clock.now() < deadline:
            clock.sleep(0.01)
        self._handshake(handshake_timeout_s)

    def take_over(self) -> None:
        """A board found running: its own targets become the ones commanded (so a wait or a
        move starts from what it holds); its modes and latched faults are in ``latest``."""
        st = self._telemetry.state()
        closed = [i for i, f in enumerate(st.fingers) if f.closed_loop]
        self._goals.forget()
        self._goals.set(closed, [st.fingers[i].target for i in closed])

    def _handshake(self, timeout_s: float) -> None:
        for attempt in range(3):
            self._session.handshake_begins()
            identity = self._session.link.handshake(timeout_s)
            try:
                self._configure(identity)
                return
            except BoardResetError:
                if attempt == 2:
                    raise
                log.info("utrf hand: the board reset during set-up; handshaking again")

    def _configure(self, identity: m.Identity) -> None:
        if identity.finger_count != len(self._fingers):
            raise ProtocolError(
                f"the board drives {identity.finger_count} fingers, the hand file names "
                f"{len(self._fingers)}"
            )
        self._session.identify(identity)
        self._telemetry.resume()
        self._configuration.read_limits()
        self._goals.forget()
        self._session.handshaken()

    # --- lifetime -------------------------------------------------------------------------------

    @property
    def closed(self) -> bool:
        return self._session.closed

    def close(self) -> None:
        """Stop telemetry, leave the fingers in the ``on_close`` mode, say ``goodbye`` (the
        board's host-silence rule stands down: a pose left in ``hold`` stays held and latches
        no HOST_TIMEOUT) and close the link. A board that reset or went away is only closed
        (nothing can be sent to it)."""
        session = self._session
        if session.closed:
            return
        try:
            if session.live:
                if self.on_close != "hold":
                    mode = m.ControlMode.BRAKE if self.on_close == "brake" else m.ControlMode.COAST
                    self._control.send_modes(ALL_FINGERS, [mode] * len(self._fingers))
                session.link.heartbeat_period_s = None  # goodbye: the last frame it hears
                self._telemetry.silence()
                session.request(m.Goodbye())
        except (ProtocolError, OSError) as exc:
            log.warning("utrf hand: could not leave the hand in %s mode: %s", self.on_close, exc)
        finally:
            session.closed = True
            self._telemetry.stop_log()
            session.link.close()

    def reconnect(self, timeout_s: float = 10.0) -> m.Identity:
        """After a ``BoardResetError`` or ``DisconnectedError``: open the line again if it went
        away (riding out the auto-reset), handshake, restart telemetry. The fingers stay as the
        board left them (after a reset: COAST); command them again."""
        session = self._session
        if session.closed:
            raise DisconnectedError("the hand was closed")
        deadline = session.clock.now() + timeout_s
        try:
            session.link.request(m.Heartbeat())
            alive = True
        except DisconnectedError:
            alive = False
        except (BoardResetError, ReplyTimeout, NackError):
            alive = True
        if not alive:
            if session.url is None:
                raise DisconnectedError("the link is gone and this hand has no URL to reopen")
            self._reopen(session.url, deadline)
            remaining = max(deadline - session.clock.now(), 0.5)
            self.start(min(2.5, remaining), remaining)
        else:
            self._handshake(max(deadline - session.clock.now(), 0.5))
        return session.identity

    def _reopen(self, url: str, deadline: float) -> None:
        """A new Link on the same URL (the port may take a moment to come back)."""
        session = self._session
        session.link.close()
        last: Exception | None = None
        while True:
            try:
                forward = TelemetryForward()
                link = open_link(url, session.baudrate, forward, self.reset_on_open)
                break
            except DisconnectedError as exc:
                last = exc
                if session.clock.now() >= deadline:
                    raise DisconnectedError(f"could not reopen {url}: {last}") from exc
                session.clock.sleep(0.2)
        session.replace_link(link)
        forward.attach(self._telemetry.on_frames)
