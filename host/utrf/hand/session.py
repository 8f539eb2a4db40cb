"""The Hand's session with its board: the link, the state every part of the Hand shares,
requests, finger names, and the board's counters.

:class:`HandSession` is the base of :class:`~utrf.hand.Hand`; its parts build on it one job
each: :mod:`~utrf.hand.telemetry` (what the board reports), :mod:`~utrf.hand.lifecycle`
(connecting, closing, reconnecting), :mod:`~utrf.hand.control` (targets and modes),
:mod:`~utrf.hand.motion` (moves, poses, settling), :mod:`~utrf.hand.configuration` (the
board's settings).
"""

from __future__ import annotations

import logging
import random
import threading
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any, Literal, Protocol, TypeVar

import numpy as np

from utrf.hand.clock import Clock
from utrf.hand.errors import TargetError
from utrf.hand.state import STATE_CLOCK_WRAP_S, BoardClock, FaultEvent, HandState, TipModel
from utrf.hand.telemetry_log import TelemetryLog
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.errors import BoardResetError, DisconnectedError, ProtocolError
from utrf.protocol.link import Link, LinkStats, Telemetry

if TYPE_CHECKING:
    from utrf.hand.motion import MoveResult

log = logging.getLogger("utrf.hand.client")  # one logger for every part, named as it always was

R = TypeVar("R", bound=Message)
FingerKey = int | str
Kind = Literal["theta2", "q", "flexion"]
OnClose = Literal["brake", "coast", "hold"]

ON_CLOSE = ("brake", "coast", "hold")
ALL_FINGERS = (1 << m.FINGER_COUNT) - 1

#: default telemetry rate: a sample every 10 ms, 7 % of the line
DEFAULT_TELEMETRY_HZ = 100


class LinkLike(Protocol):
    """What the Hand needs of its link: :class:`~utrf.protocol.link.Link` or a SimLink."""

    @property
    def identity(self) -> m.Identity | None: ...

    def request(
        self, msg: Request[R], *, timeout_s: float | None = None, retries: int | None = None
    ) -> R: ...

    def handshake(self, timeout_s: float = 3.0) -> m.Identity: ...

    heartbeat_period_s: float | None

    def stats(self) -> LinkStats: ...

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None: ...

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None: ...

    def close(self) -> None: ...


class TelemetryForward:
    """A telemetry callback that exists before its Hand does: the link is built (and starts
    reading) first, so frames that arrive meanwhile (a ``boot``) are kept and handed over."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._target: Callable[[Telemetry], None] | None = None
        self._early: list[Telemetry] = []

    def __call__(self, item: Telemetry) -> None:
        with self._lock:
            target = self._target
            if target is None:
                self._early.append(item)
                return
        target(item)

    def attach(self, target: Callable[[Telemetry], None]) -> None:
        with self._lock:
            early, self._early = self._early, []
            self._target = target
        for item in early:
            target(item)


def open_link(url: str, baudrate: int, forward: TelemetryForward, reset: bool) -> Link:
    """A Link on ``url``; the board reset by the open or not (``serial_port.open_line``)."""
    from utrf.hand.serial_port import open_line
    from utrf.protocol.transport import SerialTransport

    def opener() -> Link:
        # No queue: the Hand takes every frame through its callback (a queue nobody read
        # counted each frame as "dropped"); real loss is stream_lost.
        return Link(SerialTransport(url, baudrate), on_telemetry=forward, telemetry_queue_size=0)

    return open_line(url, reset, opener)


def finger_mask(idx: Iterable[int]) -> int:
    """The wire's finger bitmask (bit i: finger i) of finger indices."""
    return sum(1 << i for i in set(idx))


class HandSession:
    """The link to one board and the state the Hand's parts share. Not used alone: build a
    :class:`~utrf.hand.Hand`."""

    def __init__(
        self,
        link: LinkLike,
        clock: Clock,
        *,
        geometry: HandGeometry | None = None,
        poses: PoseLibrary | None = None,
        telemetry_hz: int = DEFAULT_TELEMETRY_HZ,
        on_close: OnClose = "brake",
        forward: TelemetryForward | None = None,
        url: str | None = None,
        baudrate: int = m.DEFAULT_BAUD,
    ) -> None:
        """Wrap a link that is open but not yet handshaken; :meth:`connect` and
        :meth:`emulated` do this and the handshake."""
        if on_close not in ON_CLOSE:
            raise ValueError(f"on_close must be one of {ON_CLOSE}, got {on_close!r}")
        if not 0 <= telemetry_hz <= m.MAX_TELEMETRY_HZ:
            raise ValueError(
                f"telemetry_hz must lie in 0..{m.MAX_TELEMETRY_HZ} Hz, got {telemetry_hz}"
            )
        self.link = link
        self.clock = clock
        self.geometry = geometry or HandGeometry.default()
        self._poses = poses
        self.url = url
        self.baudrate = baudrate
        self.on_close: OnClose = on_close
        self.fingers: tuple[str, ...] = tuple(f.name for f in self.geometry.fingers)
        if len(self.fingers) != m.FINGER_COUNT:
            raise ValueError(
                f"the protocol drives {m.FINGER_COUNT} fingers; the hand file has "
                f"{len(self.fingers)}"
            )
        # State shared by the parts, under _lock (telemetry arrives on the reader thread).
        self._lock = threading.Lock()
        # telemetry: the stream and what it reports
        self._telemetry_hz = int(telemetry_hz)
        # Held while callbacks run, so an unsubscribe returns only once no call is under way
        # (re-entrant: a callback may unsubscribe itself).
        self._dispatch_lock = threading.RLock()
        self._board_clock = BoardClock(STATE_CLOCK_WRAP_S)  # the state's ms clock
        self._fault_clock = BoardClock()  # the fault message's µs clock
        self._tips = TipModel(self.geometry)
        self._status: m.Status | None = None  # the latest status (modes, faults)
        self._latest: HandState | None = None
        self._state_callbacks: list[Callable[[HandState], None]] = []
        self._fault_callbacks: list[Callable[[FaultEvent], None]] = []
        self._faults_seen: list[FaultEvent] = []
        self._log: TelemetryLog | None = None
        # lifecycle: a reset seen, the handshake, closing
        self._reset: BoardResetError | None = None
        self._last_boot: m.Boot | None = None
        self._handshaken = False
        self._closed = False
        self._identity: m.Identity | None = None
        self._reset_on_open = True  # how reconnect() reopens the line
        # control and motion: the limits targets are checked against, what was commanded
        self._limits: list[tuple[float, float]] = [
            f.geometry.theta2_range_rad for f in self.geometry.fingers
        ]
        self._goal = np.full(m.FINGER_COUNT, np.nan)  # the last Joint-2 targets commanded
        # A fresh move id per Hand: a board that kept the last session's move cannot take
        # this session's first for a resend of it.
        self._move_id = random.randrange(0x10000)
        self._last_move: MoveResult | None = None
        # the link's frames reach _on_telemetry through _forward (which kept any early ones)
        self._forward = forward or TelemetryForward()
        if forward is None:
            link.add_telemetry_callback(self._forward)
        self._forward.attach(self._on_telemetry)

    def _on_telemetry(self, item: Telemetry) -> None:
        """Take one stream frame: :class:`~utrf.hand.telemetry.HandTelemetry` does."""
        raise NotImplementedError

    # --- identity and fingers -------------------------------------------------------------------

    @property
    def identity(self) -> m.Identity:
        if self._identity is None:
            raise ProtocolError("no handshake yet")
        return self._identity

    @property
    def last_boot(self) -> m.Boot | None:
        """The board's last ``boot`` message (reset cause, where its configuration came
        from), None if none was seen since the link opened."""
        with self._lock:
            return self._last_boot

    def finger_index(self, key: FingerKey) -> int:
        """0..4 for a finger name or index; TargetError naming the choices otherwise."""
        if isinstance(key, bool):
            raise TargetError(f"finger must be a name or an index, got {key!r}")
        if isinstance(key, int | np.integer):
            if 0 <= int(key) < len(self.fingers):
                return int(key)
            raise TargetError(f"finger index {key} is outside 0..{len(self.fingers) - 1}")
        if isinstance(key, str):
            if key in self.fingers:
                return self.fingers.index(key)
            if key.isdigit():
                return self.finger_index(int(key))
            raise TargetError(f"no finger named {key!r}; fingers are {list(self.fingers)}")
        raise TargetError(f"finger must be a name or an index, got {key!r}")

    def _finger_set(self, fingers: Iterable[FingerKey] | FingerKey | None) -> list[int]:
        if fingers is None:
            return list(range(len(self.fingers)))
        if isinstance(fingers, int | str):
            return [self.finger_index(fingers)]
        out = sorted({self.finger_index(f) for f in fingers})
        if not out:
            raise TargetError("no fingers given")
        return out

    # --- requests -------------------------------------------------------------------------------

    def _request(self, msg: Request[R], **kwargs: Any) -> R:
        if self._closed:
            raise DisconnectedError("the hand was closed")
        return self.link.request(msg, **kwargs)

    def _check_alive(self) -> None:
        """Raise what the next request would: a reset noticed from telemetry."""
        with self._lock:
            reset = self._reset if self._handshaken else None
        if reset is not None:
            raise reset

    def _set_mode_raw(
        self,
        mask: int,
        modes: Sequence[m.ControlMode],
        duty: Sequence[float] | None = None,
        effort: Sequence[float] | None = None,
    ) -> None:
        n = len(self.fingers)
        self._request(
            m.SetMode(
                mask=mask,
                mode=tuple(modes),
                duty=tuple(duty) if duty is not None else (0.0,) * n,
                effort=tuple(effort) if effort is not None else (0.0,) * n,
            )
        )

    def _read_limits(self) -> None:
        """The Joint-2 limits the board holds, which move and pose check targets against."""
        for i in range(len(self.fingers)):
            lim = self._request(m.GetLimits(finger=i))
            self._limits[i] = (lim.theta2_min, lim.theta2_max)

    # --- counters -------------------------------------------------------------------------------

    def stats(self) -> m.Stats:
        """The board's link and timing counters."""
        return self._request(m.GetStats())

    def reset_stats(self) -> None:
        self._request(m.ResetStats())

    def link_stats(self) -> LinkStats:
        """The host side's counters (frames, retries, CRC errors, stream frames lost...)."""
        return self.link.stats()

    def ping(self) -> float:
        """One round trip (s): wall clock, or simulated time on a driven board."""
        t0 = self.clock.now()
        self._request(m.Ping(token=0x55AA))
        return self.clock.now() - t0
