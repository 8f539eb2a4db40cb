"""Connecting to a board, riding out its auto-reset, the handshake, closing in a safe mode,
and reconnecting after a reset or a lost line."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Self

import numpy as np

from utrf.hand.clock import WallClock
from utrf.hand.session import (
    ALL_FINGERS,
    DEFAULT_TELEMETRY_HZ,
    OnClose,
    TelemetryForward,
    log,
    open_link,
)
from utrf.hand.telemetry import HandTelemetry
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary
from utrf.protocol import messages as m
from utrf.protocol.errors import (
    BoardResetError,
    DisconnectedError,
    NackError,
    ProtocolError,
    ReplyTimeout,
)

if TYPE_CHECKING:
    from utrf.emulator import EmulatedBoard


class HandLifecycle(HandTelemetry):
    """Opening, handshaking, closing and reopening (a part of :class:`~utrf.hand.Hand`)."""

    # --- building one ---------------------------------------------------------------------------

    @classmethod
    def connect(
        cls,
        url: str,
        *,
        baudrate: int = m.DEFAULT_BAUD,
        geometry: HandGeometry | None = None,
        poses: PoseLibrary | None = None,
        telemetry_hz: int = DEFAULT_TELEMETRY_HZ,
        on_close: OnClose = "brake",
        boot_wait_s: float = 2.5,
        handshake_timeout_s: float = 5.0,
        log_path: str | Path | None = None,
        reset: bool = True,
    ) -> Self:
        """Open ``url`` (``/dev/ttyACM0``, ``COM3``, ``socket://127.0.0.1:PORT``...), wait up to
        ``boot_wait_s`` for the board's ``boot`` (the auto-reset), handshake, start telemetry.

        ``boot_wait_s=0`` skips the wait (a board that does not reset when the port opens);
        a boot that comes during the handshake is ridden out all the same.

        ``reset=False`` opens the port without pulsing DTR (``utrf.hand.serial_port``), skips
        the boot wait and takes over the board as it runs: identify, read its modes, targets
        and faults, resume heartbeats; nothing moves. ``socket://`` cannot (no DTR line: a
        ResetModeError says so); the emulated board's pty and serial ports can.
        """
        forward = TelemetryForward()
        link = open_link(url, baudrate, forward, reset)
        try:
            hand = cls(
                link,
                WallClock(),
                geometry=geometry,
                poses=poses,
                telemetry_hz=telemetry_hz,
                on_close=on_close,
                forward=forward,
                url=url,
                baudrate=baudrate,
            )
            hand._reset_on_open = reset
            hand._start(boot_wait_s if reset else 0.0, handshake_timeout_s)
            if not reset:
                hand._take_over()
            if log_path is not None:
                hand.start_log(log_path)
        except BaseException:
            link.close()
            raise
        return hand

    @classmethod
    def emulated(
        cls,
        board: EmulatedBoard,
        *,
        geometry: HandGeometry | None = None,
        poses: PoseLibrary | None = None,
        telemetry_hz: int = DEFAULT_TELEMETRY_HZ,
        on_close: OnClose = "brake",
        boot_wait_s: float = 0.5,
        handshake_timeout_s: float = 3.0,
        log_path: str | Path | None = None,
    ) -> Self:
        """A Hand on an emulated board: a driven one (``realtime=False``) over a
        :class:`~utrf.hand.simlink.SimLink` in simulated time; a real-time one over its URL."""
        if board.realtime:
            if board.url is None:
                raise ValueError("the emulated board is not served (serve=False): no URL")
            return cls.connect(
                board.url,
                geometry=geometry,
                poses=poses,
                telemetry_hz=telemetry_hz,
                on_close=on_close,
                boot_wait_s=boot_wait_s,
                handshake_timeout_s=handshake_timeout_s,
                log_path=log_path,
            )
        from utrf.hand.simlink import SimLink

        forward = TelemetryForward()
        link = SimLink(board, on_telemetry=forward)
        hand = cls(
            link,
            link,
            geometry=geometry or board.plant.hand,
            poses=poses,
            telemetry_hz=telemetry_hz,
            on_close=on_close,
            forward=forward,
        )
        hand._start(boot_wait_s, handshake_timeout_s)
        if log_path is not None:
            hand.start_log(log_path)
        return hand

    def _take_over(self) -> None:
        """A board found running: its own targets become the ones commanded (so a wait or a
        move starts from what it holds); its modes and latched faults are in ``latest``."""
        st = self.state()
        for i, f in enumerate(st.fingers):
            self._goal[i] = f.target if f.closed_loop else np.nan

    def _start(self, boot_wait_s: float, handshake_timeout_s: float) -> None:
        deadline = self.clock.now() + boot_wait_s
        while self._reset is None and self.clock.now() < deadline:
            self.clock.sleep(0.01)
        self._handshake(handshake_timeout_s)

    def _handshake(self, timeout_s: float) -> None:
        for attempt in range(3):
            with self._lock:
                self._reset = None
            identity = self.link.handshake(timeout_s)
            try:
                self._configure(identity)
                return
            except BoardResetError:
                if attempt == 2:
                    raise
                log.info("utrf hand: the board reset during set-up; handshaking again")

    def _configure(self, identity: m.Identity) -> None:
        if identity.finger_count != len(self.fingers):
            raise ProtocolError(
                f"the board drives {identity.finger_count} fingers, the hand file names "
                f"{len(self.fingers)}"
            )
        self._identity = identity
        self._request(m.SetTelemetry(rate_hz=self._telemetry_hz))
        self._take_status(self._request(m.GetStatus()))
        self._read_limits()
        self._goal[:] = np.nan
        self._handshaken = True

    # --- lifetime -------------------------------------------------------------------------------

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Stop telemetry, leave the fingers in the ``on_close`` mode, say ``goodbye`` (the
        board's host-silence rule stands down: a pose left in ``hold`` stays held and latches
        no HOST_TIMEOUT) and close the link. A board that reset or went away is only closed
        (nothing can be sent to it)."""
        if self._closed:
            return
        try:
            if self._handshaken and self._reset is None:
                if self.on_close != "hold":
                    mode = m.ControlMode.BRAKE if self.on_close == "brake" else m.ControlMode.COAST
                    self._set_mode_raw(ALL_FINGERS, [mode] * len(self.fingers))
                self.link.heartbeat_period_s = None  # goodbye must be the last frame it hears
                self._request(m.SetTelemetry(rate_hz=0))
                self._request(m.Goodbye())
        except (ProtocolError, OSError) as exc:
            log.warning("utrf hand: could not leave the hand in %s mode: %s", self.on_close, exc)
        finally:
            self._closed = True
            self.stop_log()
            self.link.close()

    def reconnect(self, timeout_s: float = 10.0) -> m.Identity:
        """After a ``BoardResetError`` or ``DisconnectedError``: open the line again if it went
        away (riding out the auto-reset), handshake, restart telemetry. The fingers stay as the
        board left them (after a reset: COAST); command them again."""
        if self._closed:
            raise DisconnectedError("the hand was closed")
        deadline = self.clock.now() + timeout_s
        try:
            self.link.request(m.Heartbeat())
            alive = True
        except DisconnectedError:
            alive = False
        except (BoardResetError, ReplyTimeout, NackError):
            alive = True
        if not alive:
            if self.url is None:
                raise DisconnectedError("the link is gone and this hand has no URL to reopen")
            self._reopen(deadline)
            remaining = max(deadline - self.clock.now(), 0.5)
            self._start(min(2.5, remaining), remaining)
        else:
            self._handshake(max(deadline - self.clock.now(), 0.5))
        assert self._identity is not None
        return self._identity

    def _reopen(self, deadline: float) -> None:
        """A new Link on the same URL (the port may take a moment to come back)."""
        assert self.url is not None
        self.link.close()
        last: Exception | None = None
        while True:
            try:
                forward = TelemetryForward()
                link = open_link(self.url, self.baudrate, forward, self._reset_on_open)
                break
            except DisconnectedError as exc:
                last = exc
                if self.clock.now() >= deadline:
                    raise DisconnectedError(f"could not reopen {self.url}: {last}") from exc
                self.clock.sleep(0.2)
        self.link = link
        self._forward = forward
        with self._lock:
            self._reset = None
            self._handshaken = False
        forward.attach(self._on_telemetry)
