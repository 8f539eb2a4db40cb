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

from utrf.hand.configuration import HandConfiguration
from utrf.hand.control import KIND_UNITS, KINDS, TargetsArg
from utrf.hand.lifecycle import HandLifecycle
from utrf.hand.motion import (
    DEFAULT_MOVE_S,
    DEFAULT_TOLERANCE,
    MAX_MOVE_S,
    HandMotion,
    MoveResult,
)
from utrf.hand.session import (
    ALL_FINGERS,
    DEFAULT_TELEMETRY_HZ,
    ON_CLOSE,
    FingerKey,
    Kind,
    LinkLike,
    OnClose,
)

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


class Hand(HandLifecycle, HandMotion, HandConfiguration):
    """A connected UTRF-RoboHand. Build one with :meth:`connect` or :meth:`emulated`.

    Its parts, one job each: :class:`~utrf.hand.session.HandSession` (the link, requests,
    finger names, counters), :class:`~utrf.hand.telemetry.HandTelemetry` (state, stream,
    faults, log), :class:`~utrf.hand.lifecycle.HandLifecycle` (connect, close, reconnect),
    :class:`~utrf.hand.control.HandControl` (targets and modes),
    :class:`~utrf.hand.motion.HandMotion` (moves, poses, settling) and
    :class:`~utrf.hand.configuration.HandConfiguration` (the board's settings).
    """
