"""Seeded builds of the twin brought up, their faults against the bring-up's findings, and the
demo's tracking goal afterwards (``make bringup-campaign``; the table goes into
docs/bringup.md).

    python -m tools.bringup_campaign --builds 50 --update docs/bringup.md

Each build is ``BuildFaults.random(seed, faults)`` (every motor within ±30 % of the model's,
``faults`` faults on distinct fingers); the whole hand is brought up on a driven board
(simulated time) with the confirmation answered yes. A fault counts as named when a finding of
its kind is on its finger; a finding on a finger whose build has no fault of that kind is a
false diagnosis. A build whose findings the configuration can fix is then power-on reset (it
boots on what the bring-up saved) and runs the demo's poses (``utrf.bringup.demo_goal``: RMS
at most 1°, worst at most 3°, every pose settled). The board time of each bring-up is recorded
(the goal: a whole hand in at most 2 minutes of board time).

The builds run as tasks on Dask (``utrf.campaign.engine.cluster``: a local cluster of
``--workers`` processes, or ``--address`` of a running scheduler). Each result is appended to
``--json`` (JSON lines) as it comes; a second run with the same file skips the builds already
there (resumable), so the table can be made from several sittings.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from tools.doc_sections import cpu_name, write_section

# the twin's fault kind -> the finding that names it
EXPECTED = {
    "swap-leads": "leads-swapped",
    "swap-lead-a": "lead-a-swapped",
    "invert-magnet": "encoder-inverted",
    "magnet-offset": "magnet-offset",
    "off-centre": "not-monotonic",
    "slack": "slack",
    "weak-motor": "weak-motor",
    "slow-motor": "slow-motor",
    "narrow-range": "narrow-range",
    "friction": "friction",
    "unpowered": "no-motion",
    "unplugged": "encoder-signal",
    "swap-cables": "cable-swap",
    "swap-encoders": "cable-swap",
}
BEGIN, END = "<!-- BEGIN bringup-campaign -->", "<!-- END bringup-campaign -->"
#: the table of builds with only faults the configuration can fix (``--fixable``)
BEGIN_FIX = "<!-- BEGIN bringup-campaign-fixable -->"
END_FIX = "<!-- END bringup-campaign-fixable -->"


def run_build(
    seed: int, faults: int, demo: bool = True, fixable: bool = False, overlap: int | None = None
) -> dict[str, Any]:
    """One seeded build brought up (and its demo run when fixable); a row of the table.
    ``fixable``: its faults drawn only from the kinds the configuration can fix; ``overlap``:
    the bring-up's (default its own)."""
    from utrf.bringup import bringup
    from utrf.bringup.demo_goal import demo_goal
    from utrf.emulator import BuildFaults, EmulatedBoard
    from utrf.emulator.build_faults import FIXABLE_KINDS
    from utrf.hand import Hand

    build = BuildFaults.random(seed, faults, kinds=FIXABLE_KINDS if fixable else None)
    truth = {(EXPECTED[k], f) for k, fs in build.faults() for f in fs}
    t0 = time.monotonic()
    goal: dict[str, Any] | None = None
    with EmulatedBoard(realtime=False, seed=seed, build=build) as board:
        with Hand.emulated(board) as hand:
            more = {} if overlap is None else {"overlap": overlap}
            result = bringup(hand, confirm=lambda text: True, **more)
            found = {(fd.kind, hand.finger_index(fd.finger)) for fd in result.findings}
            detail = [_measured(r) for r in result.fingers]
        bringup_wall = time.monotonic() - t0
        if demo and result.ok:
            board.reset("power_on")  # it boots on what the bring-up saved
            with Hand.emulated(board) as hand:
                goal = demo_goal(hand).to_dict()
    return {
        "seed": seed,
        "n_faults": faults,
        "fixable_only": fixable,
        "faults": [f"{k}:{','.join(map(str, fs))}" for k, fs in build.faults()],
        "missed": sorted(f"{k}@{f}" for k, f in truth - found),
        "false": sorted(f"{k}@{f}" for k, f in found - truth),
        "fixable": result.ok,
        "saved": result.saved,
        "unchanged": result.unchanged,
        "board_time_s": result.board_time_s,
        "bringup_wall_s": bringup_wall,
        "wall_s": time.monotonic() - t0,
        "demo": goal,
        "fingers": detail,
    }


def _measured(r: Any) -> dict[str, Any]:
    """What a finger's bring-up measured, for tracing a miss to its measurement (no traces)."""
    return {
        "findings": {fd.kind: fd.data for fd in r.findings},
        "wiring": r.wiring,
        "stops": r.stops,
        "plant": r.plant,
        "checks": [(c.label, c.rms_rad, c.worst_rad) for c in r.checks],
        "steps_s": r.steps_s,
        "board_time_s": r.board_time_s,
    }


def _demo_cell(r: dict[str, Any]) -> str:
    d = r.get("demo")
    if d is None:
        return "- (not fixable)" if not r["fixable"] else "-"
    rms = max(v["rms"] for v in d["tracking_deg"].values())
    worst = max(v["worst"] for v in d["tracking_deg"].values())
    unsettled = "" if all(d["settled"].values()) else ", unsettled"
    return f"{'pass' if d['ok'] else 'FAIL'} ({rms:.2f} / {worst:.2f}{unsettled})"


def table(
    rows: list[dict[str, Any]],
    command: str,
    wall_s: float | None,
    workers: int,
    markers: tuple[str, str] = (BEGIN, END),
) -> str:
    lines = [
        markers[0],
        f"Measured with `{command}` on {cpu_name()} (2 cores shared with other jobs, "
        f"{workers} Dask worker(s)); board time is simulated time. Demo: the goal met or not, "
        "then the largest RMS / worst tracking error over the five fingers (°).",
        "",
        "| seed | faults | missed | false | saved | board time (s) | demo after (RMS / worst °) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['seed']} | {' '.join(r['faults']) or '-'} | {' '.join(r['missed']) or '-'} "
            f"| {' '.join(r['false']) or '-'} "
            f"| {'yes' if r['saved'] else ('unchanged' if r.get('unchanged') else 'no')} "
            f"| {r['board_time_s']:.1f} | {_demo_cell(r)} |"
        )
    missed = sum(len(r["missed"]) for r in rows)
    false = sum(len(r["false"]) for r in rows)
    worst = max((float(r["board_time_s"]) for r in rows), default=float("nan"))
    build_wall = sum(float(r.get("wall_s", 0.0)) for r in rows)
    fixable = [r for r in rows if r["fixable"]]
    passed = sum(1 for r in fixable if r.get("demo") and r["demo"]["ok"])
    lines += [
        "",
        f"{len(rows)} builds: {missed} faults missed, {false} false diagnoses; "
        f"{passed} of the {len(fixable)} fixable builds met the demo's tracking goal after "
        f"bring-up; the longest whole-hand bring-up took {worst:.1f} s of board time "
        f"(goal ≤ 120 s); each build took {build_wall / max(len(rows), 1) / 60:.1f} min of "
        "wall time on average (bring-up and demo, one worker each)"
        + (f"; {wall_s / 60:.1f} min of wall time for this sitting." if wall_s else "."),
        markers[1],
    ]
    return "\n".join(lines)


def _done(path: Path | None, faults: int, fixable: bool = False) -> dict[int, dict[str, Any]]:
    """The builds of this campaign (its fault count and kinds) already in ``path``."""
    if path is None or not path.exists():
        return {}
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return {
        r["seed"]: r
        for r in rows
        if r.get("n_faults") == faults and r.get("fixable_only", False) == fixable
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--builds", type=int, default=50)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--faults", type=int, default=3)
    ap.add_argument(
        "--seeds", default=None, help="only these seeds, e.g. 4,7,9 (re-running failing builds)"
    )
    ap.add_argument("--workers", type=int, default=None, help="local Dask workers (cores)")
    ap.add_argument("--address", default=None, help="a running Dask scheduler instead")
    ap.add_argument("--no-demo", action="store_true", help="skip the demo after bring-up")
    ap.add_argument("--fixable", action="store_true", help="only faults the configuration can fix")
    ap.add_argument(
        "--overlap", type=int, default=None, help="fingers brought up at once (1: one by one)"
    )
    ap.add_argument("--update", type=Path, help="write the table into this Markdown file")
    ap.add_argument("--json", type=Path, help="results as JSON lines (resumed from)")
    ap.add_argument(
        "--table-only", action="store_true", help="no builds run: the table of those in --json"
    )
    args = ap.parse_args()
    from distributed import as_completed

    from utrf.campaign.engine import cluster

    seeds = list(range(args.first_seed, args.first_seed + args.builds))
    if args.seeds:
        seeds = [int(x) for x in args.seeds.split(",")]
    done = _done(args.json, args.faults, args.fixable)
    todo = [] if args.table_only else [s for s in seeds if s not in done]
    print(f"{len(seeds) - len(todo)} builds done before, {len(todo)} to run", flush=True)
    t0 = time.monotonic()
    workers = 0
    if todo:
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
        with cluster(args.address, args.workers) as client:
            workers = len(client.scheduler_info(n_workers=-1)["workers"])
            futures = [
                client.submit(
                    run_build,
                    s,
                    args.faults,
                    not args.no_demo,
                    args.fixable,
                    args.overlap,
                    key=f"bringup-{s}-{int(args.fixable)}",
                )
                for s in todo
            ]
            for fut in as_completed(futures):
                if fut.status != "finished":  # the build's run raised: say so, run the rest
                    print(f"{fut.key}: {fut.exception()!r}", flush=True)
                    continue
                row = fut.result()
                done[row["seed"]] = row
                print(json.dumps(row), flush=True)
                if args.json:
                    with args.json.open("a") as fh:
                        fh.write(json.dumps(row) + "\n")
    wall = time.monotonic() - t0 if todo else None
    rows = [done[s] for s in seeds if s in done]
    command = (
        f"python -m tools.bringup_campaign --builds {args.builds} --faults {args.faults}"
        + (" --fixable" if args.fixable else "")
        + (f" --first-seed {args.first_seed}" if args.first_seed else "")
        + (f" --seeds {args.seeds}" if args.seeds else "")
    )
    markers = (BEGIN_FIX, END_FIX) if args.fixable else (BEGIN, END)
    text = table(rows, command, wall, workers or (args.workers or 0), markers)
    print(text)
    if args.update:
        write_section(args.update, text, *markers)


if __name__ == "__main__":
    main()
