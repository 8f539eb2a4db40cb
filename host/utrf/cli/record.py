"""``utrf record``: the hand's telemetry stream to an MCAP file (Foxglove, ROS 2, mcap readers);
``utrf export``: a recording or a telemetry CSV log to Parquet with SI columns and units.

``utrf record [--port URL] [--rate HZ] [--duration S] OUT.mcap`` records every sample of the
stream (1 kHz by default) until Ctrl-C or ``--duration`` and then prints what it holds and what
the stream lost, by the board's clock and by the board's and the link's counters; it exits 1
when a sample was lost. It changes no mode: a pose held stays held (``--port``), and the hand
is left braked when the command started the emulated board itself. ``docs/recording.md``.
Exit codes: 0; 1 samples lost; 2 bad input; 3 the board could not be reached.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
import time
from pathlib import Path

from utrf.cli import error
from utrf.cli._board_or_emulator import add_board_options, open_hand
from utrf.cli._hand_common import EXIT_BAD_INPUT, EXIT_NOT_DONE, EXIT_OK, guarded
from utrf.hand.client import OnClose
from utrf.protocol import messages as m


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "record",
        help="record the hand's telemetry to MCAP (Foxglove, ROS 2 JointState)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("out", type=Path, metavar="OUT.mcap", help="the recording to write")
    add_board_options(p, reset=False)  # a pose held on --port stays held
    p.add_argument(
        "--rate",
        type=int,
        default=m.MAX_TELEMETRY_HZ,
        metavar="HZ",
        help=f"telemetry rate (1..{m.MAX_TELEMETRY_HZ}, default {m.MAX_TELEMETRY_HZ})",
    )
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--pose", help="move to this pose of the library once recording")
    p.add_argument("--json", action="store_true", help="the summary as JSON (SI units)")
    p.set_defaults(handler=run_record)

    e = subparsers.add_parser(
        "export",
        help="a recording (.mcap) or telemetry log (.csv) to Parquet, SI columns and units",
        description="Columns as the telemetry CSV's (board_time_s, index_theta2_rad, ...), "
        "each column's unit in its Parquet field metadata ('unit') and in the file's "
        "('utrf.units').",
    )
    e.add_argument("source", type=Path, metavar="IN", help="a .mcap recording or .csv log")
    e.add_argument("dest", type=Path, metavar="OUT.parquet")
    e.set_defaults(handler=run_export)


@guarded("record")
def run_record(args: argparse.Namespace) -> int:
    from utrf.recording.session import Recording

    if not 1 <= args.rate <= m.MAX_TELEMETRY_HZ:
        error("record", f"--rate must lie in 1..{m.MAX_TELEMETRY_HZ} Hz, got {args.rate}")
        return EXIT_BAD_INPUT
    if args.duration is not None and not args.duration > 0:
        error("record", f"--duration must be > 0 s, got {args.duration}")
        return EXIT_BAD_INPUT
    if args.out.suffix.lower() != ".mcap":
        error("record", f"the recording's name must end in .mcap, got {args.out}")
        return EXIT_BAD_INPUT
    stop = threading.Event()
    old = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    on_close: OnClose = "hold" if args.port else "brake"
    try:
        with open_hand(args, telemetry_hz=args.rate, on_close=on_close) as hand:
            pose = hand.poses[args.pose] if args.pose else None
            with Recording(hand, args.out) as rec:
                print(f"utrf record: recording {args.rate} Hz to {rec.path} (Ctrl-C stops)")
                t0 = time.monotonic()
                if pose is not None:
                    hand.pose(pose, wait=False)
                try:
                    while not stop.is_set():
                        if args.duration is not None and time.monotonic() - t0 >= args.duration:
                            break
                        stop.wait(0.2)
                except KeyboardInterrupt:
                    pass
                summary = rec.stop()
    finally:
        signal.signal(signal.SIGTERM, old)
    if args.json:
        print(json.dumps({**summary.metadata(), "lost": summary.lost}))
    else:
        span = summary.last_board_time_s - summary.first_board_time_s
        print(
            f"utrf record: {summary.samples} samples over {span:.3f} s of board time; lost "
            f"{summary.lost} (board clock gaps {summary.board_time_gaps}, link seq gaps "
            f"{summary.link_stream_lost}, board tx dropped {summary.board_tx_dropped}); "
            f"{summary.faults} faults"
        )
    return EXIT_NOT_DONE if summary.lost else EXIT_OK


def run_export(args: argparse.Namespace) -> int:
    from utrf.recording.export import ExportError, export_parquet

    try:
        table = export_parquet(args.source, args.dest)
    except (ExportError, ValueError, OSError) as exc:
        error("export", exc)
        return EXIT_BAD_INPUT
    print(f"utrf export: {table.num_rows} samples, {table.num_columns} columns to {args.dest}")
    return EXIT_OK
