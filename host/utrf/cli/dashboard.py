"""``utrf dashboard [--port URL]``: the hand in a browser (``docs/dashboard.md``).

Without ``--port`` it starts an emulated board (the real firmware on simavr with the MuJoCo
hand). Serves a page on http://127.0.0.1:8080/ (``--http-port``): the hand in 3D at its
measured angles, each finger's Joint-2 angle, setpoint and duty plotted live, its mode and
faults, a slider per finger, the pose library as buttons, the settings (checked against the
protocol's ranges before sending; saved to EEPROM on request), recording to MCAP.
One page controls the hand at a time; the others watch. ``--host`` other than 127.0.0.1
needs a token (``--token``, or one is made and printed in the address). Runs until Ctrl-C.
Exit codes: 0; 2 bad input; 3 the board could not be reached.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from utrf.cli import error
from utrf.cli._board_or_emulator import add_board_options, open_hand
from utrf.cli._hand_common import EXIT_BAD_INPUT, EXIT_OK, guarded
from utrf.protocol import messages as m


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "dashboard",
        help="the hand in a browser: 3D view, live plots, sliders, poses, settings, recording",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_board_options(p)
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--http-port", type=int, default=8080, help="the page's port (default 8080)")
    p.add_argument(
        "--token",
        default=os.environ.get("UTRF_DASHBOARD_TOKEN"),
        help="the token a page must bring when --host is not 127.0.0.1 (default: "
        "$UTRF_DASHBOARD_TOKEN, else a new one, printed)",
    )
    p.add_argument(
        "--rate",
        type=int,
        default=m.MAX_TELEMETRY_HZ,
        metavar="HZ",
        help=f"telemetry rate (default {m.MAX_TELEMETRY_HZ}: every sample, for recording)",
    )
    p.add_argument(
        "--record-dir", type=Path, default=Path("."), help="where recordings go (default .)"
    )
    p.add_argument(
        "--hold-after",
        type=float,
        default=1.0,
        metavar="S",
        help="the page in control lost its connection for S seconds: every finger in closed "
        "loop holds where it is (default 1)",
    )
    p.add_argument(
        "--ui-hz", type=float, default=None, help="live view updates a second (default 30)"
    )
    p.add_argument(
        "--plot-hz",
        type=float,
        default=None,
        help="each chart's updates a second (default 2: livelier charts cost the page's "
        "latency, docs/dashboard.md)",
    )
    p.set_defaults(handler=run)


@guarded("dashboard")
def run(args: argparse.Namespace) -> int:
    from utrf.dashboard.access import needs_token, new_token
    from utrf.dashboard.hub import DashboardHub
    from utrf.dashboard.server import ServerOptions, serve

    if not 1 <= args.rate <= m.MAX_TELEMETRY_HZ:
        error("dashboard", f"--rate must lie in 1..{m.MAX_TELEMETRY_HZ} Hz, got {args.rate}")
        return EXIT_BAD_INPUT
    if not 0 <= args.hold_after <= 60:
        error("dashboard", f"--hold-after must lie in [0, 60] s, got {args.hold_after}")
        return EXIT_BAD_INPUT
    rates = {k: v for k, v in (("ui_hz", args.ui_hz), ("plot_hz", args.plot_hz)) if v is not None}
    if not all(0 < v <= 60 for v in rates.values()):
        error("dashboard", "--ui-hz and --plot-hz must lie in (0, 60]")
        return EXIT_BAD_INPUT
    token = args.token if needs_token(args.host) else None
    if needs_token(args.host) and not token:
        token = new_token()
    # the rates' defaults have one home: ServerOptions
    options = ServerOptions(host=args.host, port=args.http_port, token=token, **rates)
    # the hand keeps what it holds when the dashboard stops: the board's host-silence rule
    with open_hand(args, telemetry_hz=args.rate, on_close="hold" if args.port else "brake") as hand:
        hub = DashboardHub(hand, record_dir=args.record_dir, hold_after_s=args.hold_after)
        try:
            serve(hub, options, lambda url: print(f"utrf dashboard: open {url}", flush=True))
        finally:
            hub.close()
    return EXIT_OK
