"""``utrf monitor --port URL``: the hand's live telemetry.

On a terminal, a table refreshed ten times a second: per finger the mode, the measured and
target Joint-2 angles in degrees, the motor duties in percent, the fingertip in mm and the
latched faults, with the stream's measured rate and the frames lost. Elsewhere (a pipe, CI),
one line every ``--every`` seconds, or with ``--json`` one JSON object (SI) per sample.
Faults and board resets are printed as they happen; after a reset the monitor says so and
handshakes again (the board forgot the telemetry rate). Every 2 s it reads the board's
counters (``get_stats``) and says when the board's UART lost bytes (overruns of its two-byte
receive buffer, frame errors); the footer shows them with the ring's overflows and bad CRCs.

The monitor connects without resetting the board (no DTR pulse; ``--reset`` to reset it),
changes no mode and leaves the hand as it finds it: a pose held stays held. The first
connection after plugging a MEGA in resets it all the same (DTR rises; see
``utrf.hand.serial_port``), and over ``socket://`` (the emulated board's TCP port, which has
no DTR line) every connection resets it: the monitor says so; the emulated board's pty does
not. Runs until Ctrl-C or ``--duration`` seconds.
Exit codes: 0; 2 bad input; 3 the board could not be reached.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections import deque

from rich.console import Console
from rich.live import Live
from rich.table import Table

from utrf.cli._hand_common import EXIT_OK, add_port, connect, guarded
from utrf.hand import FaultEvent, Hand, HandState
from utrf.hand.view import state_line, state_table
from utrf.protocol import messages as m

STATS_EVERY_S = 2.0  # the board's counters (get_stats) are read this often


class _Watch:
    """Samples and events from the reader thread, for the display loop."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.times: deque[float] = deque(maxlen=1000)
        self.events: list[str] = []
        self.samples: list[HandState] = []  # for --json, printed by the display loop
        self.as_json = False
        self.board: m.Stats | None = None  # the board's counters, read every few seconds

    def on_state(self, st: HandState) -> None:
        with self.lock:
            self.times.append(time.monotonic())
            if self.as_json:
                self.samples.append(st)

    def on_fault(self, event: FaultEvent) -> None:
        with self.lock:
            self.events.append(f"fault: {event}")

    def rate(self) -> float:
        with self.lock:
            now = time.monotonic()
            recent = [t for t in self.times if t > now - 1.0]
        return float(len(recent))

    def take(self) -> tuple[list[str], list[HandState]]:
        with self.lock:
            events, self.events = self.events, []
            samples, self.samples = self.samples, []
        return events, samples


def _json_line(st: HandState) -> str:
    return json.dumps(
        {
            "board_time_s": st.board_time,
            "seq": st.seq,
            "theta2_rad": dict(zip(st.names, st.theta2.tolist(), strict=True)),
            "target_rad": dict(zip(st.names, st.target.tolist(), strict=True)),
            "mode": {f.name: f.mode.name for f in st},
            "faults": {f.name: int(f.faults) for f in st},
        }
    )


def _footer(hand: Hand, watch: _Watch) -> str:
    ls = hand.link_stats()
    text = (
        f"{hand.url} | stream {watch.rate():.0f}/{hand.telemetry_hz} Hz, frames lost "
        f"{ls.stream_lost}, damaged {ls.crc_errors + ls.framing_errors}"
    )
    b = watch.board
    if b is not None:  # what the board lost on its side of the line
        text += (
            f" | board received: UART overruns {b.uart_overruns}, frame errors "
            f"{b.uart_frame_errors}, ring full {b.rx_overruns}, bad CRC {b.rx_crc_errors}"
        )
    return text


def _board_losses(hand: Hand, watch: _Watch) -> str | None:
    """Read the board's counters; a line when its UART lost bytes since the last read."""
    old, new = watch.board, hand.stats()
    watch.board = new
    if old is None or (new.uart_overruns, new.uart_frame_errors) == (
        old.uart_overruns,
        old.uart_frame_errors,
    ):
        return None
    return (
        f"the board's UART lost bytes: {new.uart_overruns - old.uart_overruns} overruns, "
        f"{new.uart_frame_errors - old.uart_frame_errors} frame errors since the last check"
    )


@guarded("monitor")
def run(args: argparse.Namespace) -> int:
    if not 1 <= args.rate <= m.MAX_TELEMETRY_HZ:
        raise ValueError(f"--rate must lie in 1..{m.MAX_TELEMETRY_HZ} Hz, got {args.rate}")
    if args.every <= 0:
        raise ValueError(f"--every must be > 0 s, got {args.every}")
    console = Console()
    live_view = console.is_terminal and not args.json
    watch = _Watch()
    watch.as_json = args.json
    if not args.reset and args.port.startswith("socket://"):
        print(
            f"utrf monitor: note: {args.port} has no DTR line: connecting resets the emulated "
            "board (its pty, which `utrf emulate` prints, does not)",
            file=sys.stderr,
        )
        args.reset = True
    with connect(args, telemetry_hz=args.rate, on_close="hold", log_path=args.log) as hand:
        hand.on_state(watch.on_state)
        hand.on_fault(watch.on_fault)
        boot = hand.last_boot
        end = None if args.duration is None else time.monotonic() + args.duration
        next_line = time.monotonic() + args.every
        next_stats = time.monotonic()
        ident = hand.identity
        header = (
            f"firmware {ident.fw_major}.{ident.fw_minor}.{ident.fw_patch} "
            f"(build {ident.build_id:08x}), reset cause {ident.reset_cause.name}, "
            f"configuration {ident.config_status.name}"
        )
        if not args.json:
            print(header, flush=True)

        def render() -> Table:
            return state_table(
                hand.latest, title="UTRF-RoboHand monitor", footer=_footer(hand, watch)
            )

        live = Live(get_renderable=render, console=console, refresh_per_second=10)
        if live_view:
            live.start()
        try:
            while end is None or time.monotonic() < end:
                time.sleep(0.05)
                events, samples = watch.take()
                for e in events:
                    (live.console.print if live_view else print)(e)
                for st in samples:
                    print(_json_line(st))
                if hand.last_boot is not boot:  # the board reset: say so, handshake again
                    boot = hand.last_boot  # its state is gone: hand.latest is None
                    cause = boot.reset_cause.name if boot is not None else "?"
                    msg = f"the board reset ({cause}): handshaking again"
                    (live.console.print if live_view else print)(msg)
                    hand.reconnect()
                if not args.json and time.monotonic() >= next_stats:
                    next_stats += STATS_EVERY_S
                    lost = _board_losses(hand, watch)
                    if lost:
                        (live.console.print if live_view else print)(lost)
                if not live_view and not args.json and time.monotonic() >= next_line:
                    next_line += args.every
                    now = hand.latest
                    if now is not None:
                        print(f"{state_line(now)}  [{watch.rate():.0f} Hz]", flush=True)
        except KeyboardInterrupt:
            pass
        finally:
            if live_view:
                live.stop()
        if not args.json and not live_view:
            print(_footer(hand, watch), file=sys.stderr)
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "monitor",
        help="live telemetry from the hand (degrees and mm for people)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_port(p, reset=False)
    p.add_argument("--rate", type=int, default=50, metavar="HZ", help="stream rate (50 Hz)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--every", type=float, default=1.0, metavar="S", help="without a terminal: a line every S s"
    )
    p.add_argument("--log", metavar="FILE", help="append every sample to this CSV (SI)")
    p.add_argument("--json", action="store_true", help="a JSON object (SI) per sample")
    p.set_defaults(handler=run)
