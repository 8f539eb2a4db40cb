"""``utrf campaign``: many runs on Dask, results as Parquet (docs/campaigns.md).

    utrf campaign run FILE [--out DIR] [--address tcp://HOST:8786] [--workers N]
                           [--firmware LABEL=ELF ...]
    utrf campaign report DIR [--no-plots] [--json]
    utrf campaign export DIR RUN_KEY --out DIR2   # a design: geometry, MJCF, firmware table
    utrf campaign examples                        # the campaign files shipped with utrf

FILE is a campaign TOML, or the name of a shipped example (``design-sweep``). Without
``--address`` the runs go to a local cluster of one worker per core; killed and run again
(same FILE and DIR), a campaign skips what is done. Exit codes: 0 done (runs may have
failed: the report says which and why); 2 bad input (nothing ran); 3 no cluster.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from utrf.cli import error

EXIT_OK, EXIT_BAD_INPUT, EXIT_CLUSTER = 0, 2, 3


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "campaign",
        help="design sweeps and grasp Monte Carlo on Dask; results as Parquet",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="campaign_command", metavar="ACTION")
    r = sub.add_parser("run", help="run a campaign file (skipping runs already done)")
    r.add_argument("file", help="campaign TOML, or a shipped example's name")
    r.add_argument(
        "--out", type=Path, default=None, help="results directory (default campaigns/NAME)"
    )
    r.add_argument(
        "--address",
        default=None,
        help="a Dask scheduler (default: a local cluster of this machine's cores)",
    )
    r.add_argument("--workers", type=int, default=None, help="local workers (default: cores)")
    r.add_argument(
        "--firmware",
        action="append",
        default=[],
        metavar="LABEL=ELF",
        help="an ELF for a label of [firmware] (A/B), overriding the file's",
    )
    r.set_defaults(handler=_run)
    s = sub.add_parser("report", help="what a campaign found: tables, front, maps, A/B")
    s.add_argument("dir", type=Path)
    s.add_argument("--no-plots", action="store_true")
    s.add_argument("--json", action="store_true", help="the report as JSON (SI)")
    s.set_defaults(handler=_report)
    e = sub.add_parser("export", help="a design's geometry TOML, MJCF and firmware table")
    e.add_argument("dir", type=Path)
    e.add_argument("run_key")
    e.add_argument("--out", type=Path, required=True)
    e.set_defaults(handler=_export)
    x = sub.add_parser("examples", help="the campaign files shipped with utrf")
    x.set_defaults(handler=_examples)
    p.set_defaults(handler=lambda _: (p.print_help(), EXIT_BAD_INPUT)[1])


def _example(name: str) -> Path | None:
    from importlib import resources

    ref = resources.files("utrf") / "data" / "campaigns" / f"{name}.toml"
    return Path(str(ref)) if ref.is_file() else None


def _examples(args: argparse.Namespace) -> int:
    from importlib import resources

    for ref in sorted(
        resources.files("utrf").joinpath("data", "campaigns").iterdir(), key=lambda r: r.name
    ):
        if ref.name.endswith(".toml"):
            first = next((ln for ln in ref.read_text().splitlines() if ln.startswith("#")), "")
            print(f"{ref.name[:-5]:16s} {ref}  {first.lstrip('# ')}")
    return EXIT_OK


def _run(args: argparse.Namespace) -> int:
    from utrf.campaign import engine, spec

    path = Path(args.file)
    if not path.exists() and (found := _example(args.file)) is not None:
        path = found
    firmware = {}
    for item in args.firmware:
        label, sep, elf = item.partition("=")
        if not sep or not label:
            error("campaign", f"--firmware takes LABEL=ELF, got {item!r}")
            return EXIT_BAD_INPUT
        firmware[label] = elf
    if args.workers is not None and args.workers < 1:
        error("campaign", f"--workers must be >= 1, got {args.workers}")
        return EXIT_BAD_INPUT
    try:
        campaign = spec.load(path, firmware=firmware)
        out = args.out or Path("campaigns") / campaign.name
        print(
            f"campaign {campaign.name} ({campaign.kind}, {campaign.method}) -> {out}; "
            f"{'cluster ' + args.address if args.address else 'local cluster'}",
            flush=True,
        )
        summary = engine.run(
            campaign,
            out,
            address=args.address,
            workers=args.workers,
            progress=lambda line: print(line, flush=True),
        )
    except spec.CampaignError as exc:
        error("campaign", exc)
        return EXIT_CLUSTER if "no Dask scheduler" in str(exc) else EXIT_BAD_INPUT
    print(summary.line())
    print(f"results: {out / 'results.parquet'}; utrf campaign report {out}")
    return EXIT_OK


def _report(args: argparse.Namespace) -> int:
    from utrf.campaign import report

    if not (args.dir / "campaign.toml").is_file():
        error("campaign", f"{args.dir} holds no campaign (no campaign.toml)")
        return EXIT_BAD_INPUT
    out = report.report(args.dir, plots=not args.no_plots)
    if args.json:
        json.dump(out, sys.stdout, indent=2, default=str)
        print()
    else:
        print(report.describe(out))
    return EXIT_OK


def _export(args: argparse.Namespace) -> int:
    from utrf.campaign import export
    from utrf.campaign.spec import CampaignError

    try:
        files = export.export(args.dir, args.run_key, args.out)
    except (CampaignError, ValueError) as exc:
        error("campaign", exc)
        return EXIT_BAD_INPUT
    for what, path in files.items():
        print(f"{what:10s} {path}")
    return EXIT_OK
