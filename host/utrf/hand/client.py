"""``Hand``: the UTRF-RoboHand from Python, over any pyserial URL or a driven emulated board.

    from utrf import Hand

    with Hand.connect("/dev/ttyACM0") as hand:           # or "socket://127.0.0.1:PORT"
        hand.pose("shaka", duration=1.0)                   # min-jerk, then wait until settled
        hand.move({"index": 0.5}, duration=0.5, kind="flexion")
        print(hand.state()["index"].theta2)                # rad

Units are SI (rad, m, s; duties as fractions). Fingers are named as in the hand file
(``thumb index middle ring little``) or numbered 0..4 as on the wire. Targets are Joint-2
angles (``kind="theta2"``, rad, the encoder's joint), tendon displacements (``"q"``, m) or
normalised flexions (``"flexion"``: 0 straight, 1 at θ1's upper limit).

Connecting rides out the MEGA's auto-reset: opening the port resets the board, whose
bootloader keeps it silent for 1-2 s; the Hand waits for its ``boot`` frame (up to
``boot_wait_s``) and then performs the identify and schema handshake (``SchemaMismatchError``
names both versions and hashes). After a board reset or a lost line the next call raises
(``BoardResetError``, ``DisconnectedError``); :meth:`Hand.reconnect` does the handshake again.
Nothing reconnects silently, and nothing moves again on its own after a reset.

Trajectories: :meth:`Hand.move` and :meth:`Hand.pose` stream ``set_targets`` along a
minimum-jerk path at ``TRAJECTORY_RATE_HZ`` (50 Hz): steps of 20 ms that the board's 1 kHz PID
follows smoothly, about 1.5 kB/s of the 1 Mbaud line, and a rate the host keeps without
real-time scheduling. The streamed targets are Joint-2 angles converted on the host with the
finger models (the same models the firmware's kinematics table is generated from).

Closing (``with`` or :meth:`Hand.close`) stops the stream and leaves the hand in the safe mode
``on_close``: ``"brake"`` (the default: motor terminals shorted, no power; the fingers relax
slowly instead of springing open and nothing runs without the host), ``"coast"`` (outputs off,
fingers free) or ``"hold"`` (the board keeps the last targets in closed loop; after its
heartbeat timeout it latches HOST_TIMEOUT and applies its configured safe action, HOLD by
default: what ``utrf pose`` uses to leave a pose standing).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol, TypeVar

import numpy as np

from utrf.hand.clock import Clock, WallClock
from utrf.hand.errors import (
    FingerFaultError,
    NotControlledError,
    NotSettledError,
    TargetError,
)
from utrf.hand.state import (
    CLOSED_LOOP,
    STATE_CLOCK_WRAP_S,
    BoardClock,
    FaultEvent,
    HandState,
    TipModel,
)
from utrf.hand.telemetry_log import TelemetryLog
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.poses import Pose, PoseLibrary
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.errors import (
    BoardResetError,
    DisconnectedError,
    NackError,
    ProtocolError,
    ReplyTimeout,
)
from utrf.protocol.link import Link, LinkStats, Telemetry
from utrf.trajectory import min_jerk

if TYPE_CHECKING:
    from utrf.emulator import EmulatedBoard

log = logging.getLogger(__name__)

R = TypeVar("R", bound=Message)
FingerKey = int | str
Kind = Literal["theta2", "q", "flexion"]
TargetsArg = Mapping[FingerKey, float] | Sequence[float]
OnClose = Literal["brake", "coast", "hold"]

KINDS: dict[str, m.TargetKind] = {
    "theta2": m.TargetKind.JOINT2_ANGLE,
    "q": m.TargetKind.TENDON_Q,
    "flexion": m.TargetKind.FLEXION,
}
KIND_UNITS = {"theta2": "rad", "q": "m", "flexion": ""}
ON_CLOSE = ("brake", "coast", "hold")
ALL_FINGERS = (1 << m.FINGER_COUNT) - 1

#: set_targets per second along a trajectory (see the module's docstring)
TRAJECTORY_RATE_HZ = 50.0
#: default settling tolerance on the Joint-2 angle: 2 degrees
DEFAULT_TOLERANCE = math.radians(2.0)
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

    def stats(self) -> LinkStats: ...

    def add_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None: ...

    def remove_telemetry_callback(self, callback: Callable[[Telemetry], None]) -> None: ...

    def close(self) -> None: ...


class _Forward:
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


def _open_link(url: str, baudrate: int, forward: _Forward, reset: bool) -> Link:
    """A Link on ``url``; the board reset by the open or not (``serial_port.open_line``)."""
    from utrf.hand.serial_port import open_line
    from utrf.protocol.transport import SerialTransport

    def opener() -> Link:
        # No queue: the Hand takes every frame through its callback (a queue nobody read
        # counted each frame as "dropped"); real loss is stream_lost.
        return Link(SerialTransport(url, baudrate), on_telemetry=forward, telemetry_queue_size=0)

    return open_line(url, reset, opener)  # type: ignore[return-value]


def _mode(value: m.ControlMode | str) -> m.ControlMode:
    if isinstance(value, m.ControlMode):
        return value
    try:
        return m.ControlMode[str(value).upper()]
    except KeyError:
        names = [c.name.lower() for c in m.ControlMode]
        raise ValueError(f"unknown control mode {value!r}; modes are {names}") from None


def _faulted(st: HandState, idx: Iterable[int]) -> dict[str, int]:
    return {st.fingers[i].name: int(st.fingers[i].faults) for i in idx if st.fingers[i].faults}


class Hand:
    """A connected UTRF-RoboHand. Build one with :meth:`connect` or :meth:`emulated`."""

    TRAJECTORY_RATE_HZ = TRAJECTORY_RATE_HZ

    def __init__(
        self,
        link: LinkLike,
        clock: Clock,
        *,
        geometry: HandGeometry | None = None,
        poses: PoseLibrary | None = None,
        telemetry_hz: int = DEFAULT_TELEMETRY_HZ,
        on_close: OnClose = "brake",
        forward: _Forward | None = None,
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
        self._telemetry_hz = int(telemetry_hz)
        self._lock = threading.Lock()
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
        self._reset: BoardResetError | None = None
        self._last_boot: m.Boot | None = None
        self._handshaken = False
        self._closed = False
        self._log: TelemetryLog | None = None
        self._limits: list[tuple[float, float]] = [
            f.geometry.theta2_range_rad for f in self.geometry.fingers
        ]
        self._goal = np.full(m.FINGER_COUNT, np.nan)  # the last Joint-2 targets commanded
        self._identity: m.Identity | None = None
        self._reset_on_open = True  # how reconnect() reopens the line
        self._forward = forward or _Forward()
        if forward is None:
            link.add_telemetry_callback(self._forward)
        self._forward.attach(self._on_telemetry)

    # --- building one --------------------------------------------------------------------

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
    ) -> Hand:
        """Open ``url`` (``/dev/ttyACM0``, ``COM3``, ``socket://127.0.0.1:PORT``...), wait up to
        ``boot_wait_s`` for the board's ``boot`` (the auto-reset), handshake, start telemetry.

        ``boot_wait_s=0`` skips the wait (a board that does not reset when the port opens);
        a boot that comes during the handshake is ridden out all the same.

        ``reset=False`` opens the port without pulsing DTR (``utrf.hand.serial_port``), skips
        the boot wait and takes over the board as it runs: identify, read its modes, targets
        and faults, resume heartbeats; nothing moves. ``socket://`` cannot (no DTR line: a
        ResetModeError says so); the emulated board's pty and serial ports can.
        """
        forward = _Forward()
        link = _open_link(url, baudrate, forward, reset)
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
    ) -> Hand:
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

        forward = _Forward()
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

    def _read_limits(self) -> None:
        """The Joint-2 limits the board holds, which move and pose check targets against."""
        for i in range(len(self.fingers)):
            lim = self._request(m.GetLimits(finger=i))
            self._limits[i] = (lim.theta2_min, lim.theta2_max)

    # --- lifetime ------------------------------------------------------------------------

    def __enter__(self) -> Hand:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Stop telemetry, leave the fingers in the ``on_close`` mode, close the link. A
        board that reset or went away is only closed (nothing can be sent to it)."""
        if self._closed:
            return
        try:
            if self._handshaken and self._reset is None:
                if self.on_close != "hold":
                    mode = m.ControlMode.BRAKE if self.on_close == "brake" else m.ControlMode.COAST
                    self._set_mode_raw(ALL_FINGERS, [mode] * len(self.fingers))
                self._request(m.SetTelemetry(rate_hz=0))
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
                forward = _Forward()
                link = _open_link(self.url, self.baudrate, forward, self._reset_on_open)
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

    # --- identity and state --------------------------------------------------------------

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

    @property
    def telemetry_hz(self) -> int:
        return self._telemetry_hz

    @property
    def latest(self) -> HandState | None:
        """The most recent sample (telemetry or ``state()``), None before the first."""
        with self._lock:
            return self._latest

    @property
    def faults_seen(self) -> list[FaultEvent]:
        """Every ``fault`` message received since connecting (or ``forget_faults``)."""
        with self._lock:
            return list(self._faults_seen)

    def forget_faults(self) -> None:
        with self._lock:
            self._faults_seen.clear()

    def state(self) -> HandState:
        """Ask the board for its state now (``get_state``; and ``get_status`` when the
        sample names a status not received yet)."""
        msg = self._request(m.GetState())
        with self._lock:
            status = self._status
        if status is None or status.change != msg.status_seq:
            self._take_status(self._request(m.GetStatus()))
        host_time = self.clock.timestamp()
        with self._lock:
            st = HandState.from_message(
                msg,
                self.fingers,
                self._status,
                self._tips,
                board_time=self._board_clock.unwrap(msg.board_time, host_time),
                host_time=host_time,
            )
            if self._latest is None or st.board_time >= self._latest.board_time:
                self._latest = st
        return st

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

    # --- telemetry -----------------------------------------------------------------------

    def set_telemetry(self, rate_hz: int) -> None:
        """Stream the hand's state at ``rate_hz`` (0 stops; at most 500 Hz)."""
        if not 0 <= rate_hz <= m.MAX_TELEMETRY_HZ:
            raise ValueError(f"rate_hz must lie in 0..{m.MAX_TELEMETRY_HZ}, got {rate_hz}")
        self._request(m.SetTelemetry(rate_hz=int(rate_hz)))
        self._telemetry_hz = int(rate_hz)

    def on_state(self, callback: Callable[[HandState], None]) -> Callable[[], None]:
        """Call ``callback(HandState)`` for every telemetry sample (from the link's reader
        thread on a real link: keep it short). Returns a function that unsubscribes; once it
        returns, the callback is not called again."""
        return self._subscribe(self._state_callbacks, callback)

    def _subscribe(self, callbacks: list[Callable[[Any], None]], callback: Callable[[Any], None]):
        with self._lock:
            callbacks.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in callbacks:
                    callbacks.remove(callback)
            with self._dispatch_lock:
                pass  # a call under way has returned

        return unsubscribe

    def _dispatch(self, callbacks: list[Callable[[Any], None]], item: object) -> None:
        with self._dispatch_lock:
            for cb in list(callbacks):
                if cb in callbacks:  # not unsubscribed by an earlier callback
                    cb(item)

    def on_fault(self, callback: Callable[[FaultEvent], None]) -> Callable[[], None]:
        """Call ``callback(FaultEvent)`` whenever a finger latches a fault. Returns a function
        that unsubscribes."""
        return self._subscribe(self._fault_callbacks, callback)

    def start_log(self, path: str | Path) -> TelemetryLog:
        """Log every telemetry sample to a CSV file (appended when its columns match)."""
        log_ = TelemetryLog(path, self.fingers)
        with self._lock:
            old, self._log = self._log, log_
        if old is not None:
            old.close()
        return log_

    def stop_log(self) -> None:
        with self._lock:
            old, self._log = self._log, None
        if old is not None:
            old.close()

    def _take_status(self, msg: m.Status) -> None:
        """A status (stream or get_status reply): the newest by change count is kept."""
        with self._lock:
            old = self._status
            if old is None or (msg.change - old.change) % 256 < 128:
                self._status = msg

    def _on_telemetry(self, item: Telemetry) -> None:
        msg = item.message
        host_time = self.clock.timestamp()
        if isinstance(msg, m.Status):
            self._take_status(msg)
        elif isinstance(msg, m.State):
            with self._lock:
                st = HandState.from_message(
                    msg,
                    self.fingers,
                    self._status,
                    self._tips,
                    board_time=self._board_clock.unwrap(msg.board_time, host_time),
                    host_time=host_time,
                    seq=item.seq,
                )
                self._latest = st
                log_ = self._log
            if log_ is not None:
                try:
                    log_.write(st)
                except (OSError, ValueError) as exc:
                    log.error("utrf hand: telemetry log %s failed: %s", log_.path, exc)
            self._dispatch(self._state_callbacks, st)
        elif isinstance(msg, m.Fault):
            with self._lock:
                event = FaultEvent(
                    finger=self.fingers[msg.finger],
                    index=msg.finger,
                    new_faults=msg.new_faults,
                    faults={n: msg.faults[i] for i, n in enumerate(self.fingers)},
                    board_time=self._fault_clock.unwrap(msg.board_time, host_time),
                    host_time=host_time,
                )
                self._faults_seen.append(event)
            self._dispatch(self._fault_callbacks, event)
        elif isinstance(msg, m.Boot):
            with self._lock:
                self._last_boot = msg
                self._board_clock.restart()
                self._fault_clock.restart()
                self._status = None
                self._reset = BoardResetError(msg)
                self._latest = None

    # --- requests ------------------------------------------------------------------------

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

    def _fault_error(self, exc: NackError, during: str) -> FingerFaultError:
        f = exc.detail if exc.detail < len(self.fingers) else None
        try:
            st = self.state()
            faults = {x.name: int(x.faults) for x in st if x.faults}
        except ProtocolError:
            faults = {}
        if f is not None and self.fingers[f] not in faults:
            faults[self.fingers[f]] = 0
        return FingerFaultError(faults, during)

    # --- targets and modes ---------------------------------------------------------------

    def _targets(self, targets: TargetsArg, kind: str, during: str) -> dict[int, float]:
        if kind not in KINDS:
            raise TargetError(f"{during}: kind must be one of {list(KINDS)}, got {kind!r}")
        if isinstance(targets, Mapping):
            items = [(self.finger_index(k), v) for k, v in targets.items()]
        elif isinstance(targets, str) or not isinstance(targets, Sequence | np.ndarray):
            raise TargetError(
                f"{during}: targets must be a mapping finger -> value or a sequence of "
                f"{len(self.fingers)} values, got {targets!r}"
            )
        else:
            values = list(targets)
            if len(values) != len(self.fingers):
                raise TargetError(
                    f"{during}: {len(values)} targets for {len(self.fingers)} fingers"
                )
            items = list(enumerate(values))
        out: dict[int, float] = {}
        for i, v in items:
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
                raise TargetError(f"{during}: target of {self.fingers[i]} is not a number: {v!r}")
            if not math.isfinite(float(v)):
                raise TargetError(f"{during}: target of {self.fingers[i]} is {v}")
            out[i] = float(v)
        if not out:
            raise TargetError(f"{during}: no targets given")
        return out

    def to_theta2(self, finger: FingerKey, value: float, kind: Kind = "theta2") -> float:
        """A target of any kind as the Joint-2 angle (rad), with the host's finger model."""
        g = self.geometry.fingers[self.finger_index(finger)].geometry
        if kind == "theta2":
            return float(value)
        if kind == "q":
            return float(kinematics.theta2_from_q(g, value))
        if kind == "flexion":
            return float(kinematics.theta2_from_q(g, kinematics.q_from_flexion(g, value)))
        raise TargetError(f"kind must be one of {list(KINDS)}, got {kind!r}")

    def _describe_limits(self, i: int) -> str:
        lo, hi = self._limits[i]
        return f"[{lo:.3f}, {hi:.3f}] rad ([{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg)"

    def _check_limits(self, theta2: Mapping[int, float], during: str) -> None:
        for i, t in theta2.items():
            lo, hi = self._limits[i]
            if not lo - 1e-4 <= t <= hi + 1e-4:
                raise TargetError(
                    f"{during}: finger {self.fingers[i]!r} target {t:.3f} rad "
                    f"({math.degrees(t):.1f} deg) is outside its Joint-2 limits "
                    f"{self._describe_limits(i)}"
                )

    def set_targets(
        self, targets: TargetsArg, *, kind: Kind = "theta2", enable: bool = True
    ) -> None:
        """Set targets at once (a step), in ``kind``'s unit, sent as that kind (the board
        converts q and flexion with its kinematics table and refuses what lies beyond a
        finger's limits: TargetError naming it). ``enable``: fingers not under closed-loop
        control are switched to POSITION."""
        values = self._targets(targets, kind, "set_targets")
        mask = sum(1 << i for i in values)
        wire = [values.get(i, 0.0) for i in range(len(self.fingers))]
        try:
            self._request(m.SetTargets(kind=KINDS[kind], mask=mask, value=tuple(wire)))
        except NackError as exc:
            if exc.code == m.ErrorCode.OUT_OF_RANGE and exc.detail & 0x80:
                i = exc.detail & 0x7F
                unit = KIND_UNITS[kind]
                raise TargetError(
                    f"set_targets: the board refused finger {self.fingers[i]!r}'s target "
                    f"{kind} = {values.get(i, math.nan):g}{(' ' + unit) if unit else ''}: "
                    f"beyond its Joint-2 limits {self._describe_limits(i)}"
                    + (" (flexion targets lie in 0..1)" if kind == "flexion" else "")
                ) from exc
            raise
        for i, v in values.items():
            self._goal[i] = self.to_theta2(i, v, kind)
        if enable:
            self._ensure_position(sorted(values), keep_closed=True)

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

    def set_mode(
        self,
        mode: m.ControlMode | str,
        fingers: Iterable[FingerKey] | FingerKey | None = None,
        *,
        duty: float | Mapping[FingerKey, float] = 0.0,
        effort: float | Mapping[FingerKey, float] = 1.0,
    ) -> None:
        """Set the control mode (``"coast" "brake" "position" "duty" "grasp"``) of some
        fingers (default all). ``duty`` (DUTY, signed, positive flexes) and ``effort`` (GRASP:
        the largest closing duty) are fractions, one for all or per finger. A finger with a
        latched fault cannot be driven: FingerFaultError."""
        mode_ = _mode(mode)
        idx = self._finger_set(fingers)
        n = len(self.fingers)

        def per_finger(value: float | Mapping[FingerKey, float], name: str) -> list[float]:
            if isinstance(value, Mapping):
                out = [0.0] * n
                for k, v in value.items():
                    out[self.finger_index(k)] = float(v)
            else:
                out = [float(value)] * n
            lo = -1.0 if name == "duty" else 0.0
            for i in idx:
                if not lo <= out[i] <= 1.0:
                    raise ValueError(
                        f"{name} of {self.fingers[i]} must lie in [{lo:g}, 1], got {out[i]}"
                    )
            return out

        duties = per_finger(duty, "duty")
        efforts = per_finger(effort, "effort")
        modes = [m.ControlMode.COAST] * n
        for i in idx:
            modes[i] = mode_
        try:
            self._set_mode_raw(sum(1 << i for i in idx), modes, duties, efforts)
        except NackError as exc:
            if exc.code == m.ErrorCode.FAULTED:
                raise self._fault_error(exc, f"set_mode {mode_.name}") from exc
            raise
        if mode_ not in CLOSED_LOOP:
            self._goal[idx] = np.nan

    def coast(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Motor outputs off: the fingers are free."""
        self.set_mode(m.ControlMode.COAST, fingers)

    def brake(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Motor terminals shorted: unpowered, motion is damped."""
        self.set_mode(m.ControlMode.BRAKE, fingers)

    def hold(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Hold where the fingers are now, in closed loop."""
        idx = self._finger_set(fingers)
        st = self.state()
        self.set_targets({i: st.fingers[i].theta2 for i in idx}, enable=False)
        self._ensure_position(idx, keep_closed=False)

    def _ensure_position(self, idx: Sequence[int], keep_closed: bool) -> None:
        """Put fingers in POSITION; with ``keep_closed``, those in GRASP stay in GRASP."""
        st = self.state()
        todo = [
            i
            for i in idx
            if not (
                st.fingers[i].mode == m.ControlMode.POSITION
                or (keep_closed and st.fingers[i].closed_loop)
            )
        ]
        if todo:
            self.set_mode(m.ControlMode.POSITION, todo)

    # --- trajectories --------------------------------------------------------------------

    def move(
        self,
        targets: TargetsArg,
        duration: float = 1.0,
        *,
        kind: Kind = "theta2",
        wait: bool = True,
        tolerance: float = DEFAULT_TOLERANCE,
        timeout: float | None = None,
        mode: m.ControlMode | str = m.ControlMode.POSITION,
        effort: float = 1.0,
        rate_hz: float = TRAJECTORY_RATE_HZ,
    ) -> None:
        """Move fingers to targets along a minimum-jerk path over ``duration`` s, streaming
        Joint-2 targets at ``rate_hz``; with ``wait``, then :meth:`wait_settled`.

        Each finger starts from the target the board holds (closed loop) or where it is
        (otherwise), so nothing jumps. ``mode``: POSITION, or GRASP with ``effort`` (the
        largest closing duty) for the fingers that close by more than ``tolerance`` (those that
        open or stay move in POSITION). Fingers not named keep what they do. A fault latched
        during the move stops it with FingerFaultError.
        """
        if not (math.isfinite(duration) and duration >= 0):
            raise ValueError(f"duration must be a finite number of seconds >= 0, got {duration}")
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        mode_ = _mode(mode)
        if mode_ not in CLOSED_LOOP:
            raise ValueError(f"move needs POSITION or GRASP, got {mode_.name}")
        values = self._targets(targets, kind, "move")
        end = {i: self.to_theta2(i, v, kind) for i, v in values.items()}
        self._check_limits(end, "move")
        idx = sorted(end)
        st = self.state()
        faulted = _faulted(st, idx)
        if faulted:
            raise FingerFaultError(faulted, "move")
        start = {
            i: (st.fingers[i].target if st.fingers[i].closed_loop else st.fingers[i].theta2)
            for i in idx
        }
        a = np.array([start[i] for i in idx])
        b = np.array([end[i] for i in idx])
        self._send_joint2(idx, a)
        seen = len(self.faults_seen)
        if mode_ == m.ControlMode.GRASP:
            # GRASP bounds the controller's output both ways: a finger that opens or stays
            # goes in POSITION, so a gentle effort does not leave it lagging on the way out.
            closing = [i for i in idx if end[i] > start[i] + tolerance]
            opening = [i for i in idx if i not in closing]
            if closing:
                self.set_mode(m.ControlMode.GRASP, closing, effort=effort)
        else:
            opening = idx
        todo = [i for i in opening if st.fingers[i].mode != m.ControlMode.POSITION]
        if todo:
            self.set_mode(m.ControlMode.POSITION, todo)
        self._goal[idx] = b
        t0 = self.clock.now()
        k = 0
        while duration > 0:
            k += 1
            due = t0 + k / rate_hz
            self.clock.sleep(due - self.clock.now())
            t = self.clock.now() - t0
            if t >= duration:
                break
            self._check_new_faults(seen, idx, "move")
            self._send_joint2(idx, min_jerk(a, b, duration, t))
        self._send_joint2(idx, b)
        self._check_new_faults(seen, idx, "move")
        if wait:
            self.wait_settled(
                tolerance,
                timeout if timeout is not None else max(3.0, duration + 2.0),
                fingers=idx,
            )

    def _send_joint2(self, idx: Sequence[int], values: np.ndarray) -> None:
        wire = [0.0] * len(self.fingers)
        for i, v in zip(idx, values, strict=True):
            wire[i] = float(v)
        self._request(
            m.SetTargets(
                kind=m.TargetKind.JOINT2_ANGLE, mask=sum(1 << i for i in idx), value=tuple(wire)
            )
        )

    def _check_new_faults(self, seen: int, idx: Sequence[int], during: str) -> None:
        self._check_alive()
        with self._lock:
            new = [e for e in self._faults_seen[seen:] if e.index in idx]
        if new:
            raise FingerFaultError({e.finger: int(e.faults[e.finger]) for e in new}, during)

    @property
    def poses(self) -> PoseLibrary:
        """The pose library (built-in, then ~/.config/utrf/poses.toml), loaded on first use."""
        if self._poses is None:
            self._poses = PoseLibrary.load(hand=self.geometry)
        return self._poses

    def pose(
        self,
        pose: str | Pose,
        duration: float = 1.0,
        *,
        wait: bool = True,
        tolerance: float = DEFAULT_TOLERANCE,
        timeout: float | None = None,
    ) -> Pose:
        """Move to a pose of the library (by name) or a :class:`~utrf.poses.Pose`. A grasp
        pose closes its fingers in GRASP mode with its effort (see :meth:`move`); they count as
        settled when they reach their targets or stop against the object."""
        p = self.poses[pose] if isinstance(pose, str) else pose
        theta2 = p.theta2(self.geometry)
        if p.grasp is not None:
            self.move(
                list(theta2),
                duration,
                wait=wait,
                tolerance=tolerance,
                timeout=timeout,
                mode=m.ControlMode.GRASP,
                effort=p.grasp.effort,
            )
        else:
            self.move(list(theta2), duration, wait=wait, tolerance=tolerance, timeout=timeout)
        return p

    def wait_settled(
        self,
        tolerance: float = DEFAULT_TOLERANCE,
        timeout: float = 3.0,
        *,
        fingers: Iterable[FingerKey] | FingerKey | None = None,
        settle_time: float = 0.1,
    ) -> HandState:
        """Wait until every finger is within ``tolerance`` (rad) of its target for
        ``settle_time`` s; NotSettledError after ``timeout`` s naming each finger still off and
        by how much. Fingers: those given, else those the Hand has targets for, else those in
        closed loop. The target is the last one commanded (the board's own if none was).
        A GRASP finger also counts as settled when it has stopped (moved less than a quarter of
        the tolerance over ``settle_time``): it holds an object. Raises FingerFaultError when a
        finger latches a fault, NotControlledError when one leaves closed loop."""
        if not tolerance > 0 or not timeout >= 0:
            raise ValueError(f"tolerance must be > 0 and timeout >= 0, got {tolerance}, {timeout}")
        st = self._fresh_state(None)
        if fingers is not None:
            idx = self._finger_set(fingers)
        else:
            idx = [i for i in range(len(self.fingers)) if np.isfinite(self._goal[i])]
            if not idx:
                idx = [i for i in range(len(self.fingers)) if st.fingers[i].closed_loop]
        if not idx:
            return st
        period = 1.0 / self._telemetry_hz if self._telemetry_hz else 0.02
        period = min(max(period, 0.002), 0.02)
        start = self.clock.now()
        ok_since: float | None = None
        history: list[tuple[float, np.ndarray]] = []
        while True:
            now = self.clock.now()
            st = self._fresh_state(st)
            faulted = _faulted(st, idx)
            if faulted:
                raise FingerFaultError(faulted, "wait_settled")
            idle = {
                st.fingers[i].name: st.fingers[i].mode.name
                for i in idx
                if not st.fingers[i].closed_loop
            }
            if idle:
                raise NotControlledError(idle, "wait_settled")
            theta = st.theta2
            history.append((now, theta))
            while history and history[0][0] < now - settle_time - 1e-9:
                history.pop(0)
            goal = np.where(np.isfinite(self._goal), self._goal, st.target)
            err = goal - theta
            if now - start >= settle_time and len(history) > 1:
                stopped = np.abs(theta - history[0][1]) < tolerance / 4
            else:
                stopped = np.zeros(len(self.fingers), dtype=bool)
            good = all(
                abs(err[i]) <= tolerance
                or (st.fingers[i].mode == m.ControlMode.GRASP and stopped[i])
                for i in idx
            )
            if good:
                if ok_since is None:
                    ok_since = now
                if now - ok_since >= settle_time:
                    return st
            else:
                ok_since = None
            if now - start >= timeout:
                off = {self.fingers[i]: float(err[i]) for i in idx if abs(err[i]) > tolerance}
                if not off:  # settled only just now: not for settle_time yet
                    off = {self.fingers[i]: float(err[i]) for i in idx}
                raise NotSettledError(off, tolerance, timeout)
            self.clock.sleep(period)

    def _fresh_state(self, previous: HandState | None) -> HandState:
        """The latest telemetry sample if it is newer than ``previous`` and recent; else ask."""
        self._check_alive()
        st = self.latest
        if (
            st is not None
            and self._telemetry_hz
            and (previous is None or st.board_time > previous.board_time)
            and self.clock.timestamp() - st.host_time < max(5.0 / self._telemetry_hz, 0.1)
        ):
            return st
        return self.state()

    # --- configuration -------------------------------------------------------------------

    def gains(self, finger: FingerKey) -> m.Gains:
        return self._request(m.GetGains(finger=self.finger_index(finger)))

    def set_gains(self, finger: FingerKey, **changes: float) -> m.Gains:
        """Change some of a finger's controller gains (``kp``, ``ki``, ``kd``,
        ``d_cutoff_hz``, ``deadband_duty``, ``slew_per_s``, ``max_duty``, ``pretension_duty``);
        the others keep their values. Returns the gains now in use."""
        i = self.finger_index(finger)
        current = self.gains(i)
        new = self._changed(current, changes, "set_gains")
        self._request(m.SetGains(**{f.name: getattr(new, f.name) for f in m.SetGains.FIELDS}))
        return self.gains(i)

    def limits(self, finger: FingerKey) -> m.Limits:
        return self._request(m.GetLimits(finger=self.finger_index(finger)))

    def set_limits(self, finger: FingerKey, **changes: float) -> m.Limits:
        """Change some of a finger's supervision limits (``theta2_min``, ``theta2_max``,
        ``limit_margin``, ``stall_error``, ``stall_motion``, ``stall_time``,
        ``encoder_jump``; SI). Returns the limits now in use."""
        i = self.finger_index(finger)
        current = self.limits(i)
        new = self._changed(current, changes, "set_limits")
        self._request(m.SetLimits(**{f.name: getattr(new, f.name) for f in m.SetLimits.FIELDS}))
        lim = self.limits(i)
        self._limits[i] = (lim.theta2_min, lim.theta2_max)
        return lim

    def safety(self) -> m.Safety:
        return self._request(m.GetSafety())

    def set_safety(
        self,
        *,
        heartbeat_timeout: float | None = None,
        safe_action: m.SafeAction | str | None = None,
    ) -> m.Safety:
        """The host-silence rule: ``heartbeat_timeout`` (s) and ``safe_action`` (``"hold"`` or
        ``"coast"``)."""
        current = self.safety()
        if isinstance(safe_action, str):
            try:
                safe_action = m.SafeAction[safe_action.upper()]
            except KeyError:
                raise ValueError(
                    f"safe_action must be one of {[a.name.lower() for a in m.SafeAction]}, "
                    f"got {safe_action!r}"
                ) from None
        self._request(
            m.SetSafety(
                heartbeat_timeout=current.heartbeat_timeout
                if heartbeat_timeout is None
                else heartbeat_timeout,
                safe_action=current.safe_action if safe_action is None else safe_action,
            )
        )
        return self.safety()

    def finger_config(self, finger: FingerKey) -> m.FingerConfig:
        return self._request(m.GetFingerConfig(finger=self.finger_index(finger)))

    def set_finger_config(self, finger: FingerKey, **changes: Any) -> m.FingerConfig:
        """Change a finger's hardware configuration (``actuation``, ``encoder_offset``,
        ``encoder_invert``, ``motor_invert``). The finger must be idle (COAST or BRAKE)."""
        i = self.finger_index(finger)
        current = self.finger_config(i)
        new = self._changed(current, changes, "set_finger_config")
        self._request(
            m.SetFingerConfig(**{f.name: getattr(new, f.name) for f in m.SetFingerConfig.FIELDS})
        )
        return self.finger_config(i)

    @staticmethod
    def _changed(current: Message, changes: Mapping[str, Any], during: str) -> Any:
        names = {f.name for f in type(current).FIELDS} - {"finger"}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise TypeError(f"{during}: unknown field(s) {unknown}; fields are {sorted(names)}")
        return replace(current, **changes)  # type: ignore[type-var]

    def save_config(self) -> None:
        """Write the running configuration to the board's EEPROM (about 1 s)."""
        self._request(m.SaveConfig())

    def load_config(self, source: m.ConfigSource | str = m.ConfigSource.EEPROM) -> None:
        """Replace the running configuration with the saved one (``"eeprom"``) or the
        firmware's defaults (``"defaults"``). Every finger must be idle."""
        if isinstance(source, str):
            try:
                source = m.ConfigSource[source.upper()]
            except KeyError:
                raise ValueError(f"source must be 'eeprom' or 'defaults', got {source!r}") from None
        self._request(m.LoadConfig(source=source))
        self._read_limits()

    def calibrate_zero(self, fingers: Iterable[FingerKey] | FingerKey) -> None:
        """Take the present readings as Joint-2 angle 0 (fingers straight and idle)."""
        idx = self._finger_set(fingers)
        self._request(m.CalibrateZero(mask=sum(1 << i for i in idx)))

    def clear_faults(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Clear latched faults. The fingers stay in COAST: command them again."""
        idx = self._finger_set(fingers)
        self._request(m.ClearFaults(mask=sum(1 << i for i in idx)))
        self._goal[idx] = np.nan

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
