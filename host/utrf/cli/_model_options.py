"""Options and helpers shared by the finger models' commands (:mod:`utrf.cli.models`):
the finger, a pose, the loads and the limits from the command line; JSON out; errors to
exit codes; numbers for people."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from utrf.cli import error
from utrf.models import kinematics, statics, tendons
from utrf.models.geometry import FingerGeometry, GeometryError, HandGeometry

EXIT_BAD_INPUT = 2
EXIT_REFUSED = 3
EXIT_NOT_CONVERGED = 1


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--finger",
        metavar="FILE",
        help="finger geometry TOML, or a finger name of the default hand (default: "
        "host/utrf/data/geometry/finger.toml)",
    )
    p.add_argument("--json", action="store_true", help="print JSON (SI units) instead of a table")


def add_pose(p: argparse.ArgumentParser, required: bool) -> None:
    g = p.add_mutually_exclusive_group(required=required)
    g.add_argument("--q", type=float, metavar="Q", help="tendon displacement q, m")
    g.add_argument("--q-mm", type=float, metavar="Q", help="tendon displacement q, mm")
    g.add_argument("--theta2-deg", type=float, metavar="DEG", help="Joint-2 angle, degrees")
    g.add_argument("--flexion", type=float, metavar="F", help="normalised flexion (1: theta1 max)")
    g.add_argument(
        "--tip-mm", type=float, nargs=2, metavar=("X", "Y"), help="nearest reachable tip point, mm"
    )


def add_loads(p: argparse.ArgumentParser) -> None:
    p.add_argument("--load-kg", type=float, default=0.0, metavar="KG", help="payload at the tip")
    p.add_argument(
        "--force-n",
        type=float,
        nargs=2,
        default=(0.0, 0.0),
        metavar=("FX", "FY"),
        help="tip force in the finger frame, N",
    )
    p.add_argument("--moment-nm", type=float, default=0.0, metavar="M", help="tip moment, N m")
    p.add_argument(
        "--grasp-n",
        type=float,
        default=0.0,
        metavar="F",
        help="object's push on the fingertip, normal to Link 3 against flexion, N",
    )
    p.add_argument("--no-gravity", action="store_true", help="ignore the links' own weight")
    p.add_argument("--model", choices=statics.MODELS, default=statics.DEFAULT_MODEL)


def add_limits(p: argparse.ArgumentParser) -> None:
    d = tendons.Limits()
    p.add_argument(
        "--breaking-stress-mpa",
        type=float,
        default=d.tendon_breaking_stress_pa / 1e6,
        metavar="MPA",
        help="tendon breaking stress (assumed, see docs/models.md)",
    )
    p.add_argument("--min-safety-factor", type=float, default=d.min_safety_factor, metavar="SF")
    p.add_argument(
        "--rated-force-n",
        type=float,
        default=d.actuator_rated_force_n,
        metavar="N",
        help="actuator rated pull (assumed, see docs/models.md)",
    )


def geometry_from(args: argparse.Namespace) -> FingerGeometry:
    if not args.finger:
        return FingerGeometry.default()
    path = Path(args.finger)
    if path.suffix != ".toml" and not path.exists():
        hand = HandGeometry.default()
        try:
            return hand.fingers[hand.index(args.finger)].geometry
        except KeyError as exc:
            raise GeometryError(
                f"--finger {args.finger!r}: no such file, and {exc.args[0]}"
            ) from None
    return FingerGeometry.from_toml(path)


def q_from_pose(args: argparse.Namespace, geom: FingerGeometry) -> tuple[float, float | None]:
    """The pose's q (m) and, for a tip request, its distance to the nearest reachable point."""
    if args.q is not None:
        return args.q, None
    if args.q_mm is not None:
        return args.q_mm * 1e-3, None
    if args.theta2_deg is not None:
        return float(kinematics.q_from_theta2(geom, math.radians(args.theta2_deg))), None
    if args.flexion is not None:
        return float(kinematics.q_from_flexion(geom, args.flexion)), None
    if args.tip_mm is not None:
        near = kinematics.q_for_tip(geom, np.asarray(args.tip_mm) * 1e-3)
        return float(near.q), float(near.distance_m)
    return 0.0, None


def load_from(args: argparse.Namespace) -> statics.Load:
    return statics.Load(
        payload_kg=args.load_kg,
        tip_force_n=tuple(args.force_n),
        tip_moment_nm=args.moment_nm,
        grasp_force_n=args.grasp_n,
        gravity=not args.no_gravity,
    )


def limits_from(args: argparse.Namespace) -> tendons.Limits:
    return tendons.Limits(
        tendon_breaking_stress_pa=args.breaking_stress_mpa * 1e6,
        min_safety_factor=args.min_safety_factor,
        actuator_rated_force_n=args.rated_force_n,
    )


def emit(obj: dict[str, Any]) -> None:
    print(json.dumps(obj, indent=2, allow_nan=False))


def guarded(fn: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        try:
            return fn(args)
        except (GeometryError, ValueError, OSError) as exc:
            error(args.command, exc)
            return EXIT_BAD_INPUT

    return run


def deg(a: float) -> str:
    return f"{math.degrees(a):8.2f}"


def mm(v: float) -> str:
    return f"{v * 1e3:9.3f}"
