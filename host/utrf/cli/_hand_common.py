"""What the hand commands (``pose``, ``monitor``, ``demo``) share: options, the pose library,
connecting, and turning errors into one line on stderr and an exit code.

Exit codes: 0 done; 1 the hand did not do it (not settled, a latched fault, a finger not idle
when it must be); 2 bad input (an unknown pose, a bad file or value, a setting outside the
protocol's range: nothing was sent); 3 the board could not be reached or spoke another
protocol (no answer, not a UTRF board, a reset, a lost line, a schema mismatch); 4 the board
is in use (the emulated board already has a host attached, or the OS says another program
holds the port); 130 interrupted (Ctrl-C: the command says what it left).
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from utrf.cli import error
from utrf.hand import DEFAULT_TELEMETRY_HZ, Hand, HandError, TargetError
from utrf.hand.client import OnClose
from utrf.hand.errors import FingerFaultError, NotControlledError, NotSettledError
from utrf.hand.view import state_line
from utrf.models.geometry import GeometryError, HandGeometry
from utrf.poses import PoseError, PoseLibrary, user_pose_file
from utrf.protocol import messages as m
from utrf.protocol.errors import NoAnswerError, NotABoardError, PortBusyError, ProtocolError

EXIT_OK = 0
EXIT_NOT_DONE = 1
EXIT_BAD_INPUT = 2
EXIT_LINK = 3
EXIT_BUSY = 4
EXIT_INTERRUPTED = 130


def add_port(p: argparse.ArgumentParser, *, reset: bool = True, emulated: bool = False) -> None:
    """--port, --baud, --boot-wait, and --no-reset (or --reset where ``reset`` is False: the
    command then connects without resetting the board unless asked). ``emulated``: --port may
    be left out, and the command starts an emulated board (``_board_or_emulator``)."""
    p.add_argument(
        "--port",
        required=not emulated,
        metavar="URL",
        help="the board: a serial port (/dev/ttyACM0, COM3) or a pyserial URL "
        "(socket://127.0.0.1:PORT, which `utrf emulate` prints)"
        + ("; default: an emulated board started for this command" if emulated else ""),
    )
    p.add_argument(
        "--baud", type=int, default=m.DEFAULT_BAUD, help=f"default {m.DEFAULT_BAUD} (8N1)"
    )
    p.add_argument(
        "--boot-wait",
        type=float,
        default=2.5,
        metavar="S",
        help="seconds to wait for the board's boot frame after opening the port (a MEGA "
        "resets when its USB port opens; its bootloader keeps it silent 1-2 s); 0 skips",
    )
    if reset:
        p.add_argument(
            "--no-reset",
            dest="reset",
            action="store_false",
            help="connect without resetting the board (no DTR pulse): take over what it is "
            "doing; not over socket:// (no DTR line: use the emulated board's pty)",
        )
    else:
        p.add_argument(
            "--reset",
            dest="reset",
            action="store_true",
            help="reset the board on connecting (the MEGA's auto-reset); by default the "
            "board is left running",
        )


def add_poses(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--poses",
        action="append",
        type=Path,
        default=[],
        metavar="FILE",
        help=f"more poses (TOML, like utrf/data/poses.toml); {user_pose_file()} is read "
        "too when it exists ($UTRF_POSES overrides); later files win by name",
    )


def load_poses(args: argparse.Namespace) -> PoseLibrary:
    return PoseLibrary.load(extra=args.poses)


def connect(
    args: argparse.Namespace,
    *,
    poses: PoseLibrary | None = None,
    telemetry_hz: int = DEFAULT_TELEMETRY_HZ,
    on_close: OnClose = "brake",
    log_path: str | Path | None = None,
) -> Hand:
    """:meth:`Hand.connect` on ``--port`` with the common options."""
    return Hand.connect(
        args.port,
        baudrate=args.baud,
        boot_wait_s=args.boot_wait,
        reset=getattr(args, "reset", True),
        poses=poses,
        telemetry_hz=telemetry_hz,
        on_close=on_close,
        log_path=log_path,
    )


def finger_arg(text: str) -> int:
    """A finger by name (``thumb index middle ring little``) or number 0..4, checked before
    connecting (argparse's ``type``)."""
    names = [f.name for f in HandGeometry.default().fingers]
    if text in names:
        return names.index(text)
    if text.isdigit() and int(text) < len(names):
        return int(text)
    raise argparse.ArgumentTypeError(f"no finger {text!r}; fingers are {names} or 0..4")


def connect_running(args: argparse.Namespace, command: str, **kwargs: Any) -> Hand:
    """:func:`connect` for a command that leaves the board running (no reset unless
    ``--reset``); over socket://, which has no DTR line, every connection resets the emulated
    board: said on stderr."""
    if not args.reset and args.port.startswith("socket://"):
        print(
            f"utrf {command}: note: {args.port} has no DTR line: connecting resets the emulated "
            "board (its pty, which `utrf emulate` prints, does not)",
            file=sys.stderr,
        )
        args.reset = True
    return connect(args, **kwargs)


def interrupted(hand: Hand, command: str) -> int:
    """Ctrl-C during a command: the fingers under closed-loop control are held where they are
    now (POSITION at the measured angle), those driven open-loop (DUTY) are braked; says so
    and what it left, and leaves them so (goodbye: no HOST_TIMEOUT). Exit code 130."""
    hand.on_close = "hold"
    try:
        st = hand.state()
        held = [f.name for f in st if f.closed_loop and not f.faults]
        braked = [f.name for f in st if f.mode == m.ControlMode.DUTY and not f.faults]
        if held:
            hand.hold(held)
        if braked:
            hand.brake(braked)
        print(state_line(hand.state()), flush=True)
        what = []
        if held:
            what.append(f"held where they were (POSITION at the measured angle): {', '.join(held)}")
        if braked:
            what.append(f"braked (they ran open-loop): {', '.join(braked)}")
        error(command, "interrupted; " + ("; ".join(what) or "no finger was moving"))
    except (HandError, ProtocolError, OSError) as exc:
        error(command, f"interrupted, and the fingers could not be held: {exc}")
    return EXIT_INTERRUPTED


def guarded(command: str) -> Callable[[Callable[[argparse.Namespace], int]], Callable[..., int]]:
    """Errors to one line on stderr and the module's exit codes."""

    def wrap(fn: Callable[[argparse.Namespace], int]) -> Callable[..., int]:
        @functools.wraps(fn)
        def run(args: argparse.Namespace) -> int:
            try:
                return fn(args)
            except BrokenPipeError:  # `utrf monitor | head`: the reader has gone, quietly
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
                return EXIT_OK
            except (NotSettledError, FingerFaultError, NotControlledError) as exc:
                error(command, exc)
                return EXIT_NOT_DONE
            except PortBusyError as exc:
                error(command, exc)
                return EXIT_BUSY
            except (NotABoardError, NoAnswerError) as exc:  # they say what happened
                error(command, exc)
                return EXIT_LINK
            except ProtocolError as exc:
                error(command, f"{type(exc).__name__}: {exc}")
                return EXIT_LINK
            except (PoseError, GeometryError, TargetError, KeyError, ValueError) as exc:
                error(command, exc.args[0] if isinstance(exc, KeyError) else exc)
                return EXIT_BAD_INPUT
            except OSError as exc:
                error(command, f"{type(exc).__name__}: {exc}")
                return EXIT_LINK
            except HandError as exc:
                error(command, exc)
                return EXIT_NOT_DONE

        return run

    return wrap
