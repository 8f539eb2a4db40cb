"""``Hand``: the UTRF-RoboHand from Python, over any pyserial URL or a driven emulated board.

    from utrf import Hand

    with Hand.connect("/dev/ttyACM0") as hand:           # or "socket://127.0.0.1:PORT"
        hand.pose("shaka")                                 # one move on the board, then settled
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

Moves: :meth:`Hand.move` and :meth:`Hand.pose` send one ``move`` command; the board generates
each finger's minimum-jerk path in its 1 kHz tick, with velocity and acceleration feedforward,
and stretches a path its finger's speed or acceleration limits cannot follow (the reply says
which, and how long each path takes: :attr:`Hand.last_move`). The targets go as Joint-2 angles
converted on the host with the finger models (the same models the firmware's kinematics table
is generated from). ``set_targets`` stays for streaming targets (teleoperation): a step each.

Closing (``with`` or :meth:`Hand.close`) stops the stream and leaves the hand in the safe mode
``on_close``: ``"brake"`` (the default: motor terminals shorted, no power; the fingers relax
slowly instead of springing open and nothing runs without the host), ``"coast"`` (outputs off,
fingers free) or ``"hold"`` (the board keeps the last targets in closed loop: what ``utrf
pose`` uses to leave a pose standing). Every close ends with ``goodbye``: the board's
host-silence rule stands down, so a held pose latches no HOST_TIMEOUT and the next connection
takes over cleanly; a host that falls silent without it (killed, unplugged) still latches
HOST_TIMEOUT and the board applies its safe action.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Self

from utrf.hand.clock import Clock, WallClock
from utrf.hand.configuration import HandConfiguration
from utrf.hand.control import KIND_UNITS, KINDS, HandControl, Kind, TargetsArg
from utrf.hand.counters import HandCounters
from utrf.hand.fingers import ALL_FINGERS, FingerKey, Fingers
from utrf.hand.goals import Goals
from utrf.hand.lifecycle import ON_CLOSE, HandLifecycle, OnClose
from utrf.hand.limits import JointLimits
from utrf.hand.links import LinkLike, TelemetryForward, open_link
from utrf.hand.motion import (
    DEFAULT_MOVE_S,
    DEFAULT_TOLERANCE,
    MAX_MOVE_S,
    HandMotion,
    MoveResult,
)
from utrf.hand.session import HandSession
from utrf.hand.state import FaultEvent, HandState
from utrf.hand.telemetry import DEFAULT_TELEMETRY_HZ, HandTelemetry
from utrf.hand.via import Via
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary
from utrf.protocol import messages as m

if TYPE_CHECKING:
    from utrf.emulator import EmulatedBoard

__all__ = [
    "ALL_FINGERS",
    "DEFAULT_MOVE_S",
    "DEFAULT_TELEMETRY_HZ",
    "DEFAULT_TOLERANCE",
    "KINDS",
    "KIND_UNITS",
    "MAX_MOVE_S",
    "ON_CLOSE",
    "FingerKey",
    "Hand",
    "Kind",
    "LinkLike",
    "MoveResult",
    "OnClose",
    "TargetsArg",
]


class Hand:
    """A connected UTRF-RoboHand. Build one with :meth:`connect` or :meth:`emulated`.

    It holds its parts, one job each, and shows their methods as its own (:class:`Via`):
    :class:`~utrf.hand.session.HandSession` (the link, requests, the board's liveness),
    :class:`~utrf.hand.telemetry.HandTelemetry` (state, stream, faults, log),
    :class:`~utrf.hand.control.HandControl` (targets and modes),
    :class:`~utrf.hand.motion.HandMotion` (moves, poses, settling),
    :class:`~utrf.hand.configuration.HandConfiguration` (the board's settings),
    :class:`~utrf.hand.lifecycle.HandLifecycle` (handshake, close, reconnect) and
    :class:`~utrf.hand.counters.HandCounters` (stats, ping); they share the finger names
    (:class:`~utrf.hand.fingers.Fingers`), the Joint-2 limits
    (:class:`~utrf.hand.limits.JointLimits`) and the targets commanded
    (:class:`~utrf.hand.goals.Goals`).
    """

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
        reset_on_open: bool = True,
    ) -> None:
        """Wrap a link that is open but not yet handshaken; :meth:`connect` and
        :meth:`emulated` do this and the handshake."""
        self.geometry = geometry or HandGeometry.default()
        fingers = Fingers(f.name for f in self.geometry.fingers)
        self.fingers: tuple[str, ...] = fingers.names
        self._fingers = fingers
        session = self._session = HandSession(link, clock, url=url, baudrate=baudrate)
        limits = JointLimits(self.geometry, fingers.names)
        goals = Goals()
        self._telemetry = HandTelemetry(session, self.geometry, fingers.names, telemetry_hz)
        self._control = HandControl(session, fingers, self.geometry, self._telemetry, limits, goals)
        self._motion = HandMotion(
            session, fingers, self.geometry, self._telemetry, self._control, limits, goals, poses
        )
        self._configuration = HandConfiguration(session, fingers, limits, goals)
        self._lifecycle = HandLifecycle(
            session,
            fingers,
            self._telemetry,
            self._control,
            self._configuration,
            goals,
            on_close=on_close,
            reset_on_open=reset_on_open,
        )
        self._counters = HandCounters(session)
        # the link's frames reach the telemetry part through forward (which kept early ones)
        if forward is None:
            forward = TelemetryForward()
            link.add_telemetry_callback(forward)
        forward.attach(self._telemetry.on_frames)

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
                reset_on_open=reset,
            )
            hand._lifecycle.start(boot_wait_s if reset else 0.0, handshake_timeout_s)
            if not reset:
                hand._lifecycle.take_over()
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
        hand._lifecycle.start(boot_wait_s, handshake_timeout_s)
        if log_path is not None:
            hand.start_log(log_path)
        return hand

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- the session and its board --------------------------------------------------------------

    @property
    def link(self) -> LinkLike:
        """The link in use (a new one after :meth:`reconnect` reopened the line)."""
        return self._session.link

    @property
    def clock(self) -> Clock:
        """The Hand's clock: the wall's, or a driven board's simulated time."""
        return self._session.clock

    @property
    def url(self) -> str | None:
        return self._session.url

    @property
    def baudrate(self) -> int:
        return self._session.baudrate

    @property
    def identity(self) -> m.Identity:
        return self._session.identity

    @property
    def last_boot(self) -> m.Boot | None:
        """The board's last ``boot`` message (reset cause, where its configuration came
        from), None if none was seen since the link opened."""
        return self._session.last_boot

    def finger_index(self, key: FingerKey) -> int:
        """0..4 for a finger name or index; TargetError naming the choices otherwise."""
        return self._fingers.index(key)

    # --- lifecycle: closing, reconnecting -------------------------------------------------------

    @property
    def on_close(self) -> OnClose:
        return self._lifecycle.on_close

    @on_close.setter
    def on_close(self, value: OnClose) -> None:
        """Change what closing leaves (``utrf``'s Ctrl-C: ``"hold"`` where the fingers are)."""
        if value not in ON_CLOSE:
            raise ValueError(f"on_close must be one of {ON_CLOSE}, got {value!r}")
        self._lifecycle.on_close = value

    @property
    def closed(self) -> bool:
        return self._lifecycle.closed

    close = Via("_lifecycle", HandLifecycle.close)
    reconnect = Via("_lifecycle", HandLifecycle.reconnect)

    # --- telemetry: what the board reports ------------------------------------------------------

    @property
    def telemetry_hz(self) -> int:
        return self._telemetry.telemetry_hz

    @property
    def latest(self) -> HandState | None:
        """The most recent sample (telemetry or ``state()``), None before the first."""
        return self._telemetry.latest

    @property
    def faults_seen(self) -> list[FaultEvent]:
        """Every ``fault`` message received since connecting (or ``forget_faults``)."""
        return self._telemetry.faults_seen

    state = Via("_telemetry", HandTelemetry.state)
    set_telemetry = Via("_telemetry", HandTelemetry.set_telemetry)
    on_state = Via("_telemetry", HandTelemetry.on_state)
    on_states = Via("_telemetry", HandTelemetry.on_states)
    on_fault = Via("_telemetry", HandTelemetry.on_fault)
    forget_faults = Via("_telemetry", HandTelemetry.forget_faults)
    start_log = Via("_telemetry", HandTelemetry.start_log)
    stop_log = Via("_telemetry", HandTelemetry.stop_log)

    # --- control: targets and modes -------------------------------------------------------------

    to_theta2 = Via("_control", HandControl.to_theta2)
    set_targets = Via("_control", HandControl.set_targets)
    set_mode = Via("_control", HandControl.set_mode)
    coast = Via("_control", HandControl.coast)
    brake = Via("_control", HandControl.brake)
    hold = Via("_control", HandControl.hold)

    # --- motion: moves, poses, settling ---------------------------------------------------------

    @property
    def last_move(self) -> MoveResult | None:
        """What the board reported for the last move: its paths' durations, which were
        stretched."""
        return self._motion.last_move

    @property
    def poses(self) -> PoseLibrary:
        """The pose library (built-in, then ~/.config/utrf/poses.toml), loaded on first use."""
        return self._motion.poses

    move = Via("_motion", HandMotion.move)
    pose = Via("_motion", HandMotion.pose)
    wait_settled = Via("_motion", HandMotion.wait_settled)
    take_up = Via("_motion", HandMotion.take_up)

    # --- configuration: the board's settings ----------------------------------------------------

    gains = Via("_configuration", HandConfiguration.gains)
    set_gains = Via("_configuration", HandConfiguration.set_gains)
    motion = Via("_configuration", HandConfiguration.motion)
    set_motion = Via("_configuration", HandConfiguration.set_motion)
    limits = Via("_configuration", HandConfiguration.limits)
    set_limits = Via("_configuration", HandConfiguration.set_limits)
    safety = Via("_configuration", HandConfiguration.safety)
    set_safety = Via("_configuration", HandConfiguration.set_safety)
    finger_config = Via("_configuration", HandConfiguration.finger_config)
    set_finger_config = Via("_configuration", HandConfiguration.set_finger_config)
    save_config = Via("_configuration", HandConfiguration.save_config)
    load_config = Via("_configuration", HandConfiguration.load_config)
    calibrate_zero = Via("_configuration", HandConfiguration.calibrate_zero)
    clear_faults = Via("_configuration", HandConfiguration.clear_faults)

    # --- counters -------------------------------------------------------------------------------

    stats = Via("_counters", HandCounters.stats)
    reset_stats = Via("_counters", HandCounters.reset_stats)
    link_stats = Via("_counters", HandCounters.link_stats)
    ping = Via("_counters", HandCounters.ping)
