"""``utrf emulate``: the emulated board, served until Ctrl-C.

Runs the firmware ELF (default: ``build/firmware/utrf.elf`` in a checkout, from ``make
firmware``; installed, one built on first use into the user's cache: ``utrf.artifacts``) on simavr
with the plant model of the hand, paced to the wall clock, and serves its UART0 on a TCP port
(``socket://127.0.0.1:PORT``, for pyserial) and on a pty. Prints where to connect, a status
line now and then with the real-time factor, and takes fault-injection commands on stdin
(``help`` lists them). Exit codes: 0 stopped (Ctrl-C, SIGTERM or ``--duration``), 1 the board
failed, 2 bad input.

Angles on the command line are in degrees (Joint-2 angle), and say so; the API is SI.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

from utrf import artifacts
from utrf.cli import error
from utrf.emulator import EmulatedBoard, EmulatorError, HarnessError, PlantError
from utrf.models.geometry import GeometryError, HandGeometry

EXIT_BAD_INPUT = 2

COMMANDS_HELP = """\
commands (angles in degrees, fingers 0..4 or thumb/index/middle/ring/little):
  reset [reset_pin|power_on]  reset the board (default: reset_pin, like the auto-reset)
  hang [cli]                   hang the firmware's loop() (cli: with interrupts off too);
                               the watchdog resets the board
  unplug FINGER [VOLTS]        disconnect a Joint-2 encoder (its ADC input reads VOLTS, 0 V)
  plug FINGER                  reconnect it
  block FINGER [DEG]           jam a finger at a Joint-2 angle (default: where it is)
  obstacle FINGER DEG          an object stops the finger flexing past DEG
  unblock FINGER               free it
  noise N                      put N random bytes on the line to the board
  line drop|corrupt|insert P [to_board|to_host|both]   per-byte fault probability
  clean                        a clean line again
  status                       print the status line now
  state                        print the hand's true state (joint angles, tensions, drives)
  help, quit"""


@functools.cache
def _finger_names() -> tuple[str, ...]:
    """The fingers' names as the shipped hand file gives them (their one home)."""
    return tuple(f.name for f in HandGeometry.default().fingers)


def _finger(text: str) -> int:
    names = _finger_names()
    if text in names:
        return names.index(text)
    try:
        f = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"finger must be 0..{len(names) - 1} or one of {', '.join(names)}, got {text!r}"
        ) from None
    if not 0 <= f < len(names):
        raise argparse.ArgumentTypeError(f"finger must be 0..{len(names) - 1}, got {f}")
    return f


def _finger_value(text: str, required: bool = False) -> tuple[int, float | None]:
    """FINGER or FINGER:VALUE (the value None when absent)."""
    name, sep, value = text.partition(":")
    finger = _finger(name)
    if not sep:
        if required:
            raise argparse.ArgumentTypeError(f"expected FINGER:DEG, got {text!r}")
        return finger, None
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a number in {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{value!r} is not a finite number")
    return finger, v


def _probability(text: str) -> float:
    try:
        p = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= p <= 1.0:
        raise argparse.ArgumentTypeError(f"a probability must lie in [0, 1], got {p}")
    return p


def speed_arg(text: str) -> float | None:
    """``--speed``: an emulated board's pace, a factor of real time or ``max`` (None)."""
    if text == "max":
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"speed must be a factor > 0 or 'max', got {text!r}"
        ) from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"speed must be a factor > 0 or 'max', got {text!r}")
    return v


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "emulate",
        help="run the firmware on an emulated board and serve it on a pty and TCP",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=COMMANDS_HELP,
    )
    p.add_argument(
        "--elf",
        type=Path,
        help="firmware ELF (default: build/firmware/utrf.elf in a checkout, else built from "
        "the package's firmware sources into the user's cache)",
    )
    p.add_argument("--hand", type=Path, help="hand TOML for the plant (default: the shipped hand)")
    p.add_argument("--seed", type=int, default=0, help="seed of the encoder noise and line faults")
    p.add_argument(
        "--speed",
        type=speed_arg,
        default=1.0,
        metavar="X|max",
        help="pace at X times real time (default 1); 'max': as fast as it goes",
    )
    p.add_argument(
        "--port", type=int, default=0, help="TCP port on 127.0.0.1 (default: any free one)"
    )
    p.add_argument("--no-pty", action="store_true", help="do not open a pty")
    p.add_argument(
        "--no-auto-reset",
        action="store_true",
        help="a connecting client does not reset the board (the MEGA's DTR auto-reset)",
    )
    p.add_argument(
        "--auto-reset-hold",
        type=float,
        default=0.1,
        metavar="S",
        help="seconds a connecting client holds the board in reset (default 0.1; a stock "
        "MEGA's bootloader waits about 1 s)",
    )
    p.add_argument(
        "--eeprom", type=Path, metavar="FILE", help="EEPROM image: loaded, saved at exit"
    )
    p.add_argument("--duration", type=float, metavar="S", help="stop after S simulated seconds")
    p.add_argument(
        "--status-interval",
        type=float,
        default=5.0,
        metavar="S",
        help="seconds between status lines (0: none)",
    )
    p.add_argument("--url-file", type=Path, metavar="FILE", help="write the URLs here once serving")
    p.add_argument("--json", action="store_true", help="JSON lines instead of text (SI units)")
    p.add_argument("--no-commands", action="store_true", help="ignore stdin")
    f = p.add_argument_group("fault injection (also as commands on stdin)")
    f.add_argument(
        "--unplug-encoder",
        action="append",
        default=[],
        metavar="F[:V]",
        type=_finger_value,
        help="finger F's encoder disconnected (ADC input at V volts, default 0)",
    )
    f.add_argument(
        "--block",
        action="append",
        default=[],
        metavar="F[:DEG]",
        type=_finger_value,
        help="finger F jammed at a Joint-2 angle in degrees (default: where it starts)",
    )
    f.add_argument(
        "--obstacle",
        action="append",
        default=[],
        metavar="F:DEG",
        type=lambda t: _finger_value(t, required=True),
        help="finger F cannot flex past DEG degrees",
    )
    f.add_argument(
        "--line-drop", type=_probability, default=0.0, metavar="P", help="drop each byte with P"
    )
    f.add_argument(
        "--line-corrupt",
        type=_probability,
        default=0.0,
        metavar="P",
        help="flip a bit of each byte with P",
    )
    f.add_argument(
        "--line-insert",
        type=_probability,
        default=0.0,
        metavar="P",
        help="insert a random byte with P",
    )
    f.add_argument(
        "--line-direction",
        choices=("to_board", "to_host", "both"),
        default="both",
        help="which way the line faults act (default both)",
    )
    f.add_argument(
        "--reset-every", type=float, metavar="S", help="reset the board every S simulated seconds"
    )
    p.set_defaults(handler=run)


def build_board(args: argparse.Namespace) -> EmulatedBoard:
    """The board the options describe, faults applied (EmulatorError and friends if bad)."""
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise EmulatorError(f"--duration must be > 0 simulated seconds, got {args.duration}")
    if args.reset_every is not None and not args.reset_every > 0:
        raise EmulatorError(f"--reset-every must be > 0 seconds, got {args.reset_every}")
    if args.line_insert >= 1.0:
        raise EmulatorError("--line-insert must be below 1")
    board = EmulatedBoard(
        args.elf,
        hand=args.hand,
        seed=args.seed,
        realtime=True,
        eeprom_path=args.eeprom,
        speed=args.speed,
        tcp_port=args.port,
        pty=not args.no_pty,
        auto_reset=not args.no_auto_reset,
        auto_reset_hold=args.auto_reset_hold,
    )
    try:
        for finger, volts in args.unplug_encoder:
            board.unplug_encoder(finger, volts)
        for finger, deg in args.block:
            board.block_finger(finger, None if deg is None else math.radians(deg))
        for finger, deg in args.obstacle:
            board.block_finger(finger, math.radians(deg), direction="flexion")
        if args.line_drop or args.line_corrupt or args.line_insert:
            board.set_line_faults(
                args.line_direction,
                drop=args.line_drop,
                corrupt=args.line_corrupt,
                insert=args.line_insert,
            )
    except BaseException:
        board.close()
        raise
    return board


class _Printer:
    def __init__(self, out: TextIO, as_json: bool) -> None:
        self.out = out
        self.json = as_json
        self.lock = threading.Lock()

    def say(self, text: str, **data: Any) -> None:
        with self.lock:
            if self.json:
                print(json.dumps({"event": text.split(":")[0], **data}), file=self.out, flush=True)
            else:
                print(text, file=self.out, flush=True)


def _status(board: EmulatedBoard) -> dict[str, Any]:
    s = board.stats
    clients = [name for name, on in board.clients.items() if on]
    return {
        "sim_time_s": round(board.sim_time, 4),
        "realtime_factor": round(board.realtime_factor, 3),
        "capacity": round(board.capacity, 3),
        "status": board.status,
        "clients": clients,
        "resets": s["resets"],
        "reset_cause": board.reset_cause,
        "bytes_to_board": s["rx_uart_bytes"],
        "bytes_to_host": s["tx_uart_bytes"],
        "lag_events": board.lag_events,
    }


def _status_text(st: dict[str, Any]) -> str:
    clients = ", ".join(st["clients"]) or "none"
    return (
        f"t = {st['sim_time_s']:.1f} s simulated | real-time factor {st['realtime_factor']:.2f} "
        f"(could run {st['capacity']:.1f}x) | {st['status']} | clients: {clients} | "
        f"resets {st['resets']} | bytes in/out {st['bytes_to_board']}/{st['bytes_to_host']}"
    )


def _plant_state(board: EmulatedBoard) -> dict[str, Any]:
    """The true state of the hand, SI (rad, N, A), for people and for BoardProcess."""
    return {
        "sim_time_s": board.sim_time,
        "theta_rad": board.theta.tolist(),
        "theta2_rad": board.theta2.tolist(),
        "tension_n": board.tendon_tension.tolist(),
        "current_a": board.motor_current.tolist(),
        "drive": [[list(ch) for ch in finger] for finger in board.drive],
        "adc_volts": board.adc_volts.tolist(),
        "status": board.status,
    }


def _plant_state_text(st: dict[str, Any]) -> str:
    deg = " ".join(f"{math.degrees(a):6.1f}" for a in st["theta2_rad"])
    tension = " ".join(f"{t1:5.1f}/{t4:<5.1f}" for t1, t4 in st["tension_n"])
    return f"t = {st['sim_time_s']:.3f} s | theta2 (deg) {deg} | tendon 1/4 (N) {tension}"


def _command(board: EmulatedBoard, line: str, say: _Printer) -> bool:
    """Run one stdin command; False to quit."""
    words = line.split()
    if not words:
        return True
    cmd, rest = words[0].lower(), words[1:]
    try:
        if cmd in ("quit", "exit", "q"):
            return False
        if cmd == "help":
            say.say(COMMANDS_HELP)
        elif cmd == "status":
            st = _status(board)
            say.say(f"status: {_status_text(st)}", **st)
        elif cmd == "state":
            st = _plant_state(board)
            say.say(f"state: {_plant_state_text(st)}", **st)
        elif cmd == "hang":
            if rest not in ([], ["cli"]):
                raise ValueError(f"hang takes nothing or 'cli', got {' '.join(rest)!r}")
            board.hang_firmware(interrupts=not rest)
            say.say(f"hung: the firmware{' with interrupts off' if rest else ''}")
        elif cmd == "reset":
            board.reset(rest[0] if rest else "reset_pin")
            say.say(f"reset: {rest[0] if rest else 'reset_pin'}")
        elif cmd == "unplug":
            board.unplug_encoder(_finger(rest[0]), float(rest[1]) if len(rest) > 1 else None)
            say.say(f"unplugged: encoder of finger {rest[0]}")
        elif cmd == "plug":
            board.plug_encoder(_finger(rest[0]))
            say.say(f"plugged: encoder of finger {rest[0]}")
        elif cmd in ("block", "obstacle"):
            deg = float(rest[1]) if len(rest) > 1 else None
            if cmd == "obstacle" and deg is None:
                raise ValueError("obstacle needs an angle in degrees")
            board.block_finger(
                _finger(rest[0]),
                None if deg is None else math.radians(deg),
                direction="both" if cmd == "block" else "flexion",
            )
            say.say(f"{cmd}: finger {rest[0]}")
        elif cmd == "unblock":
            board.unblock_finger(_finger(rest[0]))
            say.say(f"unblocked: finger {rest[0]}")
        elif cmd == "noise":
            board.inject_noise(int(rest[0]))
            say.say(f"noise: {rest[0]} bytes to the board")
        elif cmd == "line":
            kind, p = rest[0], _probability(rest[1])
            if kind not in ("drop", "corrupt", "insert"):
                raise ValueError(f"line fault must be drop, corrupt or insert, got {kind!r}")
            rates = {"drop": 0.0, "corrupt": 0.0, "insert": 0.0} | {kind: p}
            board.set_line_faults(
                rest[2] if len(rest) > 2 else "both",
                drop=rates["drop"],
                corrupt=rates["corrupt"],
                insert=rates["insert"],
            )
            say.say(f"line: {kind} {p}")
        elif cmd == "clean":
            board.set_line_faults("both")
            say.say("clean: the line has no faults")
        else:
            say.say(f"error: unknown command {cmd!r} (try 'help')")
    except (IndexError, ValueError, argparse.ArgumentTypeError, EmulatorError, PlantError) as exc:
        say.say(f"error: {cmd}: {str(exc) or 'missing argument'} (try 'help')")
    return True


def _read_commands(board: EmulatedBoard, say: _Printer, stop: threading.Event) -> None:
    """Commands until "quit" (which stops the board); the end of stdin only ends the reading."""
    for line in sys.stdin:
        if stop.is_set():
            return
        if not _command(board, line, say):
            stop.set()
            return


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    out = out if out is not None else sys.stdout
    say = _Printer(out, args.json)
    try:
        board = build_board(args)
    except (EmulatorError, HarnessError, PlantError, GeometryError, OSError) as exc:
        error("emulate", exc)
        return EXIT_BAD_INPUT

    stop = threading.Event()
    failed = False
    previous = signal.getsignal(signal.SIGTERM)
    in_main = threading.current_thread() is threading.main_thread()
    if in_main:
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        pace = "as fast as it goes" if board.speed is None else f"{board.speed:g}x real time"
        firmware = artifacts.describe_firmware(board.elf, given=args.elf is not None)
        say.say(
            f"serving: firmware {firmware} on an emulated ATmega2560 (simavr, 16 MHz), "
            f"seed {board.seed}, {pace}\n"
            f"  connect: {board.url}"
            + (f"\n           {board.pty_path}" if board.pty_path else "")
            + "\n"
            "  Ctrl-C stops; 'help' on stdin lists the fault-injection commands",
            url=board.url,
            pty=board.pty_path,
            elf=str(board.elf),
            firmware=firmware,
            build_id=artifacts.firmware_build_id(board.elf),
        )
        if args.url_file is not None:
            tmp = args.url_file.with_name(f".{args.url_file.name}.{os.getpid()}")
            tmp.write_text("".join(f"{u}\n" for u in board.urls))
            os.replace(tmp, args.url_file)
        if not args.no_commands and sys.stdin is not None and not sys.stdin.closed:
            threading.Thread(target=_read_commands, args=(board, say, stop), daemon=True).start()

        next_status = time.monotonic() + args.status_interval
        next_reset = args.reset_every
        while not stop.is_set():
            stop.wait(0.05)
            if board.failure is not None:
                print(f"utrf emulate: the board stopped: {board.failure!r}", file=sys.stderr)
                failed = True
                break
            if args.duration is not None and board.sim_time >= args.duration:
                break
            if next_reset is not None and board.sim_time >= next_reset:
                board.reset()
                next_reset += args.reset_every
            if args.status_interval > 0 and time.monotonic() >= next_status:
                st = _status(board)
                say.say(f"status: {_status_text(st)}", **st)
                next_status += args.status_interval
    except KeyboardInterrupt:
        pass
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)
        st = _status(board)
        board.close()
        say.say(
            f"stopped: {st['sim_time_s']:.2f} s simulated, real-time factor "
            f"{st['realtime_factor']:.2f} (the board could run {st['capacity']:.1f}x real time "
            "on this machine)",
            **st,
        )
    return 1 if failed else 0
