"""``utrf hil``: the rig runs (``hil/README.md``).

    utrf hil static-loading --emulated --out out/static [--seed N] [--force]
    utrf hil static-loading --port /dev/ttyACM0 --tracker-port /dev/ttyUSB0 --out out/static
    utrf hil grasp-hold --emulated [--object egg] [--duration-s 600] [--out out/grasp]
    utrf hil analyse out/grasp          # results from the logs alone, a killed run's too

Options are SI except where named (``--loads-kg``); the progress lines and tables show mm and
degrees and say so. Exit codes: 0 done; 1 stopped on a fault or interrupted (the data stay;
``--resume`` continues a static loading run); 2 bad input (including payloads the planner
refuses without ``--force``); 3 the board or the tracker could not be reached.
"""

from __future__ import annotations

import argparse
import gc
import sys
from pathlib import Path
from typing import Any

from utrf.cli._hand_common import EXIT_BAD_INPUT, EXIT_LINK, EXIT_NOT_DONE, EXIT_OK, error

EMULATED_HOLD_S = 20.0  # the emulated hold's default: a minute's wait, not ten
PAPER_HOLD_S = 600.0  # the paper's hold (Sec. IV-C), the rig's default


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "hil",
        help="rig runs: static loading (paper Sec. IV-A), grasp hold (Sec. IV-C)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="hil_command", metavar="RUN")

    s = sub.add_parser(
        "static-loading",
        help="payloads at a straight finger's tip, tip tracked, model compared and calibrated",
    )
    _common(s)
    s.add_argument("--finger", default="index", help="finger name or index (default index)")
    s.add_argument("--repeats", type=int, default=3, help="repeats of the schedule (default 3)")
    s.add_argument(
        "--loads-kg",
        type=float,
        nargs="+",
        default=None,
        metavar="KG",
        help="payloads in kg (default the paper's 0.5 1.0 1.5 2.0 2.5 3.0); each repeat starts "
        "unloaded",
    )
    s.add_argument("--resume", action="store_true", help="continue the run in --out")
    s.add_argument(
        "--force",
        action="store_true",
        help="run payloads the planner calls unsafe (tendon or actuator over its rating), "
        "with a warning; the paper's 3 kg is one on the default finger",
    )
    s.add_argument(
        "--actuator-rating-n",
        type=float,
        default=None,
        metavar="N",
        help="the driving actuator's rated pull for the planner's check (default: the "
        "planner's 150 N; emulated: the rig actuator's stall force)",
    )
    s.add_argument("--settle-s", type=float, default=1.5, help="wait after a load (s)")
    s.add_argument("--record-s", type=float, default=1.0, help="recording per step (s)")
    s.add_argument("--tracker-hz", type=float, default=40.0, help="tracker samples/s (40)")
    s.set_defaults(handler=_static_loading)

    g = sub.add_parser("grasp-hold", help="hold a grasp pose under hammer hits, record drift")
    _common(g)
    g.add_argument(
        "--pose", default=None, help="a grasp pose of the library (default grasp-bottle; with "
        "--object, the object's)",
    )  # fmt: skip
    g.add_argument(
        "--object",
        default=None,
        metavar="NAME",
        help="emulated: hold a real object on the MuJoCo hand (egg, bottle, ball, box): object "
        "slip, hits, contact forces, breakage, dropped",
    )
    g.add_argument(
        "--effort", type=float, default=None, help="with --object: GRASP effort (the pose's)"
    )
    g.add_argument(
        "--duration-s",
        type=float,
        default=None,
        help=f"hold time (default: {EMULATED_HOLD_S:g} s emulated, the paper's "
        f"{PAPER_HOLD_S:g} s on the rig; --duration-s {PAPER_HOLD_S:g} for the full hold "
        "emulated)",
    )
    g.add_argument(
        "--hits",
        type=int,
        default=None,
        help="emulated hammer hits (default one per 30 s, at least one; with --object one "
        "per 10 s)",
    )
    g.add_argument(
        "--hit-impulse",
        type=float,
        default=None,
        metavar="N_S",
        help="each emulated hammer hit's impulse in newton-seconds (N·s; default 0.3 on a "
        "fingertip; on an --object, its mass x 0.025 m/s)",
    )
    g.add_argument(
        "--tracked-finger", default="index", help="the finger carrying the tracker's sensor"
    )
    g.add_argument("--sample-hz", type=float, default=50.0, help="samples/s logged (50)")
    g.set_defaults(handler=_grasp_hold)
    a = sub.add_parser(
        "analyse", help="(re)compute a run's results and figure from its logs (a killed run too)"
    )
    a.add_argument("out", type=Path, metavar="DIR", help="the run's output directory")
    a.set_defaults(handler=_analyse)
    p.set_defaults(handler=lambda _a: (p.print_help(), EXIT_BAD_INPUT)[1])


def _out(args: argparse.Namespace, kind: str, name: str, progress: Any) -> None:
    """``--out``, or a new directory named after the run (said where)."""
    from utrf.hil.runs import default_out

    if args.out is None:
        args.out = default_out(kind, name)
        progress(f"writing to {args.out}")


def _analyse(args: argparse.Namespace) -> int:
    import json

    from utrf.hil import object_hold, object_hold_report
    from utrf.hil.grasp_hold import report as grasp_report
    from utrf.hil.runs import RunError, run_kind
    from utrf.hil.static_loading import report as static_report
    from utrf.models.geometry import HandGeometry

    meta_path = args.out / "meta.json"
    if not meta_path.exists():
        error("hil analyse", f"{args.out} holds no run (no meta.json)")
        return EXIT_BAD_INPUT
    try:
        meta = json.loads(meta_path.read_text())
        kind = run_kind(meta)
    except (ValueError, RunError) as exc:
        error("hil analyse", f"{meta_path}: {exc}")
        return EXIT_BAD_INPUT
    if kind == "static-loading":
        geometry = HandGeometry.default().fingers[int(meta["config"]["finger"])].geometry
        result = static_report.write(args.out, geometry)
        print(static_report.describe(result))
        figure: Any = args.out / static_report.FIGURE if result["per_payload"] else None
    elif kind == "object-hold":
        result = object_hold_report.write(args.out)
        print(object_hold.describe(result))
        figure = result["figure"]
    else:
        result = grasp_report.write(args.out)
        print(grasp_report.describe(result))
        figure = args.out / grasp_report.FIGURE if result["samples"] else None
    print(f"results: {args.out / 'results.json'}" + (f", figure: {figure}" if figure else ""))
    return EXIT_OK


def _common(p: argparse.ArgumentParser) -> None:
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--port", metavar="URL", help="the real board (serial port or URL)")
    where.add_argument(
        "--emulated",
        action="store_true",
        help="a driven emulated board with the emulated truth and a simulated tracker",
    )
    p.add_argument("--seed", type=int, default=0, help="emulation seed (default 0)")
    p.add_argument(
        "--elf",
        default=None,
        metavar="FILE",
        help="--emulated: the firmware ELF (default: build/firmware/utrf.elf in a checkout, "
        "else built from the package's sources)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="output directory (default: a new out/RUN/NAME-DATE-TIME, printed)",
    )
    p.add_argument(
        "--tracker-port",
        default=None,
        metavar="PORT",
        help="NDI Aurora's serial port (real rig; default: probe)",
    )
    p.add_argument("--tracker-sensor", type=int, default=0, help="the tip sensor's tool (0)")
    p.add_argument("--boot-wait", type=float, default=2.5, help="s to wait for the board's boot")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def _finger(name: str) -> int:
    from utrf.models.geometry import HandGeometry

    names = [f.name for f in HandGeometry.default().fingers]
    if name in names:
        return names.index(name)
    if name.isdigit() and 0 <= int(name) < len(names):
        return int(name)
    raise ValueError(f"no finger {name!r}; fingers are {names} or 0..{len(names) - 1}")


def _open(args: argparse.Namespace, tracked: int, truth: Any = None) -> Any:
    from utrf.hil import rig

    if args.emulated:
        return rig.open_emulated(seed=args.seed, tracked_finger=tracked, truth=truth, elf=args.elf)
    from utrf.hil.tracker import NDIAuroraTracker

    tracker = NDIAuroraTracker(args.tracker_port, sensor=args.tracker_sensor)
    try:
        return rig.open_real(args.port, tracker, boot_wait_s=args.boot_wait)
    except BaseException:
        tracker.close()
        raise


def _warn_rate(tracker: Any, hz: float, option: str) -> None:
    """A sample rate above the tracker's own gives repeated frames, not more samples."""
    rate = getattr(tracker, "rate_hz", None)
    if rate is not None and hz > rate:
        print(
            f"WARNING: {option} {hz:g} is above the tracker's {rate:g} frames/s: repeated "
            "frames are not new samples (they are skipped); the run takes no more of them",
            file=sys.stderr,
            flush=True,
        )


def _run_guarded(command: str, body: Any) -> int:
    from utrf.emulator import EmulatorError, HarnessError
    from utrf.hand.errors import HandError
    from utrf.hil.runs import RunError, RunStopped
    from utrf.hil.tracker import TrackerError
    from utrf.protocol.errors import ProtocolError

    try:
        return int(body())
    except (RunStopped, HandError) as exc:
        error(command, f"stopped: {exc}; every sample taken is in the output directory")
        return EXIT_NOT_DONE
    except (RunError, ValueError, EmulatorError, HarnessError, ImportError) as exc:
        error(command, exc)  # a missing firmware, harness or tracker package: nothing written
        return EXIT_BAD_INPUT
    except TrackerError as exc:
        error(command, exc)
        return EXIT_LINK if "could not" in str(exc) else EXIT_BAD_INPUT
    except (ProtocolError, OSError) as exc:
        error(command, f"the board: {exc}")
        return EXIT_LINK
    except EOFError as exc:
        error(command, exc)
        return EXIT_NOT_DONE


def _static_loading(args: argparse.Namespace) -> int:
    from utrf.hil.rig import RIG_ACTUATOR, EmulatedTruth
    from utrf.hil.runs import default_time
    from utrf.hil.static_loading import config as sl
    from utrf.hil.static_loading import report, run
    from utrf.models.geometry import HandGeometry

    command = "hil static-loading"
    progress = (lambda _s: None) if args.quiet else (lambda s: print(s, flush=True))

    def body() -> int:
        if args.out is None and args.resume:
            error(command, "--resume needs the run's --out DIR")
            return EXIT_BAD_INPUT
        finger = _finger(args.finger)
        _out(args, "static-loading", f"finger-{finger}", progress)
        rating = args.actuator_rating_n
        if rating is None and args.emulated:
            rating = RIG_ACTUATOR.stall_force_n
        config = sl.StaticLoadingConfig(
            finger=finger,
            loads_kg=tuple(args.loads_kg) if args.loads_kg else sl.PAPER_LOADS_KG,
            repeats=args.repeats,
            settle_s=args.settle_s,
            record_s=args.record_s,
            tracker_hz=args.tracker_hz,
            force=args.force,
            actuator_rating_n=rating,
            emulated=bool(args.emulated),
            seed=args.seed,
        )
        geometry = HandGeometry.default().fingers[config.finger].geometry
        if args.resume:  # the stored configuration wins (finger, loads, seed...)
            config = run.prepare_output(args.out, config, resume=True, extra_meta={})
            geometry = HandGeometry.default().fingers[config.finger].geometry
            args.seed = config.seed
        checks, limits = run.check_loads(geometry, config)
        unsafe = [c for c in checks if not c.safe]
        for c in checks:
            progress(
                f"planner: {c.load_kg:g} kg -> actuating tendon {c.tension_n:.0f} N (safety "
                f"factor {c.safety_factor:.2f}), motor A {c.motor_force_n:.0f} N of "
                f"{limits.actuator_rated_force_n:g} N rated: {'ok' if c.safe else 'UNSAFE'}"
            )
        if unsafe and not config.force:
            for c in unsafe:
                error(command, f"refused {c.load_kg:g} kg: " + "; ".join(c.reasons))
            error(command, "the planner calls these payloads unsafe; --force runs them anyway")
            return EXIT_BAD_INPUT
        for c in unsafe:
            print(
                f"WARNING: running {c.load_kg:g} kg although the planner says: "
                + "; ".join(c.reasons)
                + " (--force)",
                file=sys.stderr,
                flush=True,
            )
        truth = EmulatedTruth() if config.emulated else None
        if not args.resume:
            run.check_new_output(args.out)
        # Everything that can fail to start (the firmware, the harness, the tracker and its
        # package, the board) before anything is written: a failed start does not block its
        # own retry.
        rig = _open(args, config.finger, truth)
        try:
            _warn_rate(rig.tracker, config.tracker_hz, "--tracker-hz")
            if not args.resume:
                meta: dict[str, Any] = {"started": default_time(), "port": args.port}
                if truth is not None:
                    meta["emulated_truth"] = truth.to_json()
                meta["planner"] = [
                    {"load_kg": c.load_kg, "safe": c.safe, "reasons": list(c.reasons)}
                    for c in checks
                ]
                run.prepare_output(args.out, config, resume=False, extra_meta=meta)
            run.run(rig, config, args.out, geometry=geometry, progress=progress)
        finally:
            rig.close()
        result = report.write(args.out, geometry)
        print(report.describe(result))
        print(f"results: {args.out / 'results.json'}, figure: {args.out / report.FIGURE}")
        return EXIT_OK if result.get("complete") else EXIT_NOT_DONE

    return _run_guarded(command, body)


def _object_hold(args: argparse.Namespace, progress: Any) -> int:
    """``grasp-hold --emulated --object NAME``: the object on the MuJoCo hand."""
    from utrf.hil import object_hold as oh

    if not args.emulated:
        error("hil grasp-hold", "--object needs --emulated (the MuJoCo hand holds the object)")
        return EXIT_BAD_INPUT
    hits = args.hits if args.hits is not None else max(1, int(args.duration_s // 10))
    _out(args, "grasp-hold", args.object, progress)
    config = oh.ObjectHoldConfig(
        object=args.object,
        pose=args.pose,
        effort=args.effort,
        duration_s=args.duration_s,
        hits=hits,
        **({} if args.hit_impulse is None else {"hit_impulse_n_s": args.hit_impulse}),
        seed=args.seed,
    )
    result = oh.run(config, args.out, elf=getattr(args, "elf", None), progress=progress)
    print(oh.describe(result))
    figure = f", figure: {result['figure']}" if result["figure"] else ""
    print(f"results: {args.out / 'results.json'}{figure}")
    return EXIT_OK if not result["dropped"] and not result["broke"] else EXIT_NOT_DONE


def _grasp_hold(args: argparse.Namespace) -> int:
    from utrf.hil.grasp_hold import config as gh
    from utrf.hil.grasp_hold import report, run
    from utrf.hil.rig import EmulatedTruth
    from utrf.hil.runs import default_time

    command = "hil grasp-hold"
    progress = (lambda _s: None) if args.quiet else (lambda s: print(s, flush=True))

    def body() -> int:
        if args.duration_s is None:
            args.duration_s = EMULATED_HOLD_S if args.emulated else PAPER_HOLD_S
        if args.object is not None:
            return _object_hold(args, progress)
        tracked = _finger(args.tracked_finger)
        hits = args.hits if args.hits is not None else max(1, int(args.duration_s // 30))
        _out(args, "grasp-hold", args.pose or "grasp-bottle", progress)
        config = gh.GraspHoldConfig(
            pose=args.pose or "grasp-bottle",
            duration_s=args.duration_s,
            hits=hits if args.emulated else 0,
            hit_impulse_n_s=0.3 if args.hit_impulse is None else args.hit_impulse,
            tracked_finger=tracked,
            sample_hz=args.sample_hz,
            emulated=bool(args.emulated),
            seed=args.seed,
        )
        # The grasp hold uses the hand's own motors (no rig actuator).
        rig = _open(args, tracked, EmulatedTruth(actuator=None))
        report.preload_plotting()  # the figure's imports, beside the hold
        # what start-up made lives to the end: the collector's full passes need not walk it
        # again during the hold (they ran while the board stood still, in the closing)
        gc.freeze()
        try:
            _warn_rate(rig.tracker, config.sample_hz, "--sample-hz")
            geometry = rig.hand.geometry
            lines = run.run(
                rig,
                config,
                args.out,
                progress=progress,
                meta={"started": default_time(), "port": args.port},
            )
        finally:
            rig.close()
        result = report.write(args.out, geometry, lines)
        print(report.describe(result))
        print(f"results: {args.out / 'results.json'}, figure: {args.out / report.FIGURE}")
        # everything is written: the interpreter's exit need not collect what the hold made
        # (about 0.2 s of a short hold's exit, docs/benchmarks.md)
        gc.freeze()
        return EXIT_OK if result.get("complete") and not result.get("faults") else EXIT_NOT_DONE

    return _run_guarded(command, body)
