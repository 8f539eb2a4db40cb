"""``utrf kinematics | statics | workspace | stiffness | calibrate | plan``: the finger models.

Every command takes ``--finger FILE`` (a geometry TOML, or the name of a finger of the default
hand, e.g. ``thumb``) and ``--json``. JSON is SI (m, rad, N, Pa); the tables for people show
mm, degrees and N, and say so. Exit codes: 0 done, 2 bad input, 3 a plan refused as unsafe,
1 statics that did not converge.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from utrf.cli._model_options import (
    EXIT_NOT_CONVERGED,
    EXIT_REFUSED,
    add_common,
    add_limits,
    add_loads,
    add_pose,
    deg,
    emit,
    geometry_from,
    guarded,
    limits_from,
    load_from,
    mm,
    q_from_pose,
)
from utrf.models import (
    calibration,
    kinematics,
    planning,
    statics,
    stiffness,
    tendons,
    workspace,
)
from utrf.models.geometry import FingerGeometry, HandGeometry


# -- kinematics -------------------------------------------------------------------------------
def _kinematics(args: argparse.Namespace) -> int:
    geom = geometry_from(args)
    q, tip_distance = q_from_pose(args, geom)
    fk = kinematics.forward(geom, q)
    joints = kinematics.joint_positions(geom, q)
    wraps = tendons.wrap_angles(geom, fk.theta)
    lo, hi = tendons.coupling_q_range_m(geom)
    out = {
        "q_m": q,
        "flexion": float(kinematics.flexion_from_q(geom, q)),
        "theta_rad": fk.theta.tolist(),
        "tip_m": fk.tip.tolist(),
        "jacobian": fk.jacobian.tolist(),
        "joints_m": joints[:3].tolist(),
        "within_q_range": bool(geom.q_range_m[0] <= q <= geom.q_range_m[1]),
        "coupling_valid": bool(lo <= q <= hi),
        "wrap_angles_rad": wraps.tolist(),
    }
    if tip_distance is not None:
        out["requested_tip_m"] = [v * 1e-3 for v in args.tip_mm]
        out["tip_distance_m"] = tip_distance
    if args.json:
        emit(out)
        return 0
    print(f"finger {geom.source}")
    print(f"q = {q * 1e3:.4f} mm, flexion {out['flexion']:.4f}")
    print("joint angles theta1..3 (deg, relative):", " ".join(deg(t) for t in fk.theta))
    print(f"tip (mm): x {fk.tip[0] * 1e3:.3f}  y {fk.tip[1] * 1e3:.3f}")
    print(f"jacobian d(tip)/dq (mm/mm): [{fk.jacobian[0]:.4f}, {fk.jacobian[1]:.4f}]")
    if tip_distance is not None:
        print(f"nearest reachable point is {tip_distance * 1e3:.3f} mm from the requested tip")
    if not out["within_q_range"]:
        print("warning: q is outside the range set by theta1_range")
    if not out["coupling_valid"]:
        print(
            f"warning: |q| > {hi * 1e3:.3f} mm: a coupling tendon would leave its guide "
            "(negative wrap); the coupling model does not hold here"
        )
    return 0


# -- statics ----------------------------------------------------------------------------------
def _statics(args: argparse.Namespace) -> int:
    geom = geometry_from(args)
    q, _ = q_from_pose(args, geom)
    load = load_from(args)
    limits = limits_from(args)

    def solve(model: str) -> statics.StaticsResult:
        return statics.solve(
            geom,
            q,
            load,
            model=model,
            threshold_m=args.threshold_m,
            max_iterations=args.max_iterations,
            limits=limits,
            relaxation=args.relaxation,
        )

    res = solve(args.model)
    out = res.to_json()
    other = None
    if args.compare:
        other_model = "printed" if args.model == "serial" else "serial"
        other = solve(other_model)
        out["compare"] = {
            "model": other_model,
            "tip_m": other.tip_m.tolist(),
            "tip_deflection_m": other.tip_deflection_m,
            "tip_difference_m": float(np.hypot(*(other.tip_m - res.tip_m))),
        }
    if args.verify:
        from utrf.models import energy

        if args.model != "serial" or load.grasp_force_n != 0:
            raise statics.StaticsError(
                "--verify checks the serial model with fixed-direction loads (no --grasp-n)"
            )
        sol = energy.solve_energy(geom, q, load)
        out["verify"] = {
            "method": "minimum potential energy (scipy BFGS, complex-step gradient)",
            "tip_m": sol.tip.tolist(),
            "tip_difference_m": float(np.hypot(*(sol.tip - res.tip_m))),
            "tension_difference_n": float(np.abs(sol.net_tensions_n - res.net_tensions_n).max()),
        }
    if args.json:
        emit(out)
    else:
        print(f"finger {geom.source}; model {res.model}; q = {q * 1e3:.4f} mm")
        print(
            f"load: payload {load.payload_kg:g} kg, force ({load.tip_force_n[0]:g}, "
            f"{load.tip_force_n[1]:g}) N, moment {load.tip_moment_nm:g} N m, grasp "
            f"{load.grasp_force_n:g} N, link gravity {'on' if load.gravity else 'off'}"
        )
        print("joint angles (deg, relative):", " ".join(deg(t) for t in res.theta_rad))
        print(
            f"tip (mm): x {res.tip_m[0] * 1e3:.3f}  y {res.tip_m[1] * 1e3:.3f}; "
            f"deflection from the unloaded tip {res.tip_deflection_m * 1e3:.3f} mm"
        )
        print(f"{'level':>5} {'tendon':>6} {'tension N':>10} {'stress MPa':>10} {'safety':>7}")
        for k in range(3):
            sf = res.safety_factor[k]
            print(
                f"{k + 1:>5} {res.loaded_tendons[k]:>6} {res.tensions_n[k]:10.2f} "
                f"{res.stress_pa[k] / 1e6:10.1f} {sf if math.isfinite(sf) else float('inf'):7.2f}"
            )
        a, b = res.motor_force_n
        print(f"motor pull (N): A {a:.2f}, B {b:.2f}; iterations {res.iterations}")
        if other is not None:
            print(
                f"{other.model} model: tip deflection {other.tip_deflection_m * 1e3:.3f} mm, "
                f"{out['compare']['tip_difference_m'] * 1e3:.3f} mm from this one"
            )
        if "verify" in out:
            v = out["verify"]
            print(
                f"energy check: tip differs by {v['tip_difference_m'] * 1e3:.2e} mm, "
                f"tensions by {v['tension_difference_n']:.2e} N"
            )
        for w in res.warnings:
            print(f"warning: {w}")
    return 0 if res.converged else EXIT_NOT_CONVERGED


# -- workspace --------------------------------------------------------------------------------
def _workspace(args: argparse.Namespace) -> int:
    geom = geometry_from(args)
    ws = workspace.swept(geom, args.resolution_mm * 1e-3)
    areas = workspace.areas(geom, fine=ws)
    if args.out:
        workspace.plot(ws, geom, args.out, extrapolated=areas)
    out = {"areas": areas.to_json(), "figure": str(args.out) if args.out else None}
    if args.json:
        emit(out)
        return 0
    a = areas.link_areas_m2 * 1e6
    print(f"finger {geom.source}; raster {args.resolution_mm:g} mm, areas extrapolated (mm²):")
    print(f"  Link 1 {a[0]:.0f}, Link 2 {a[1]:.0f}, Link 3 {a[2]:.0f}")
    print(
        f"  Links 1 and 2 overlap {areas.overlap_12_m2 * 1e6:.0f}; "
        f"all links {areas.total_area_m2 * 1e6:.0f}"
    )
    if args.out:
        print(f"wrote {args.out}")
    return 0


# -- stiffness --------------------------------------------------------------------------------
def _stiffness(args: argparse.Namespace) -> int:
    geom = geometry_from(args)
    models = statics.MODELS if args.model == "both" else (args.model,)
    q, _ = q_from_pose(args, geom)
    curves = [
        stiffness.deflection_curve(geom, args.loads_kg, q=q, model=m, gravity=not args.no_gravity)
        for m in models
    ]
    if args.out:
        stiffness.plot(curves, args.out)
    out = {
        "q_m": q,
        "models": {c.model: c.to_json() for c in curves},
        "paper": {
            "load_kg": stiffness.PAPER_LOAD_KG,
            "deflection_m": stiffness.PAPER_DEFLECTION_M,
            "stiffness_n_per_m": stiffness.PAPER_STIFFNESS_N_PER_M,
        },
        "figure": str(args.out) if args.out else None,
    }
    if args.json:
        emit(out)
        return 0
    print(f"finger {geom.source}; q = {q * 1e3:.3f} mm; deflection from the zero-payload tip (mm)")
    print(f"{'load kg':>8} " + " ".join(f"{c.model:>9}" for c in curves))
    for i, w in enumerate(curves[0].loads_kg):
        print(f"{w:8.2f} " + " ".join(mm(c.deflection_m[i]) for c in curves))
    for c in curves:
        print(
            f"{c.model}: stiffness {c.secant_stiffness_n_per_m:.4g} N/m at "
            f"{c.loads_kg.max():g} kg (least-squares slope {c.fit_stiffness_n_per_m:.4g} N/m)"
        )
    print(
        f"paper (measured): {stiffness.PAPER_DEFLECTION_M * 1e3:.3f} mm at 3 kg, "
        f"{stiffness.PAPER_STIFFNESS_N_PER_M:.4g} N/m"
    )
    if args.out:
        print(f"wrote {args.out}")
    return 0


# -- calibrate --------------------------------------------------------------------------------
def _calibrate(args: argparse.Namespace) -> int:
    geom = geometry_from(args)
    data = calibration.read_csv(args.data)
    names = [n.strip() for n in args.fit.split(",") if n.strip()] if args.fit else None
    res = calibration.fit(data, geom, fit_params=names, model=args.model)
    out = res.to_json()
    out["data"] = str(args.data)
    if args.json:
        emit(out)
        return 0
    p = out["parameters"]
    print(f"{data.source}: {len(data)} rows of {data.kind} data; model {res.model}")
    print(f"fitted {', '.join(res.fitted)}:")
    for n in res.fitted:
        sd = res.std_errors.get(n)
        if n == "modulus":
            v, unit, f = p["tendon_youngs_modulus_pa"], "GPa", 1e-9
        elif n == "q_offset":
            v, unit, f = p["q_offset_m"], "mm", 1e3
        elif n == "radius_scale":
            v, unit, f = p["guide_radii_m"][0] / geom.guide_radii_m[0], "x", 1.0
        elif n == "actuating_length":
            v, unit, f = p["actuating_tendon_length_m"], "mm", 1e3
        else:
            dx, dy = (v * 1e3 for v in p["tip_offset_m"])
            err = f" ± ({sd[0] * 1e3:.3g}, {sd[1] * 1e3:.3g})" if isinstance(sd, list) else ""
            print(f"  tip_offset = ({dx:.3f}, {dy:.3f}){err} mm")
            continue
        err = f" ± {sd * f:.3g}" if isinstance(sd, float) else ""
        print(f"  {n} = {v * f:.5g}{err} {unit}")
    length = res.finger_length_m
    print(
        f"error: mean {res.mean_error_m * 1e3:.3f} mm ({100 * res.mean_error_m / length:.3f} % of "
        f"the {length * 1e3:.0f} mm finger), max {res.max_error_m * 1e3:.3f} mm "
        f"({100 * res.max_error_m / length:.3f} %)"
    )
    print(
        f"before the fit: mean {res.initial_errors_m.mean() * 1e3:.3f} mm, max "
        f"{res.initial_errors_m.max() * 1e3:.3f} mm"
    )
    for w in res.warnings:
        print(f"warning: {w}")
    return 0


# -- plan -------------------------------------------------------------------------------------
def _plan_one(
    args: argparse.Namespace, geom: FingerGeometry, target: planning.Target
) -> planning.Plan:
    return planning.plan(
        geom,
        target,
        load_from(args),
        model=args.model,
        limits=limits_from(args),
        match=args.match,
        tolerance_m=args.tolerance_mm * 1e-3,
    )


def _print_plan(p: planning.Plan, target: planning.Target, title: str) -> None:
    s = p.statics
    print(f"{title}; target {target.kind} = {target.value}; model {s.model}")
    print(
        f"target pose: q {p.q_target_m * 1e3:.4f} mm, tip ({p.target_tip_m[0] * 1e3:.3f}, "
        f"{p.target_tip_m[1] * 1e3:.3f}) mm"
    )
    print(
        f"command: q {p.q_command_m * 1e3:.4f} mm (correction "
        f"{(p.q_command_m - p.q_target_m) * 1e3:+.4f} mm); Joint-2 setpoint "
        f"{math.degrees(p.theta2_setpoint_rad):.3f} deg"
    )
    ft = p.firmware_targets
    print(
        f"firmware targets: JOINT2_ANGLE {math.degrees(ft['JOINT2_ANGLE']):.3f} deg, "
        f"TENDON_Q {ft['TENDON_Q'] * 1e3:.4f} mm, FLEXION {ft['FLEXION']:.5f}"
    )
    print(
        f"loaded tip ({s.tip_m[0] * 1e3:.3f}, {s.tip_m[1] * 1e3:.3f}) mm, "
        f"{p.tip_error_m * 1e3:.3f} mm from the target"
    )
    print(
        "tensions (N): "
        + ", ".join(f"T{t} {v:.1f}" for t, v in zip(s.loaded_tendons, s.tensions_n, strict=True))
        + f"; motor pull A {s.motor_force_n[0]:.1f} N, B {s.motor_force_n[1]:.1f} N"
    )
    for w in p.warnings:
        print(f"warning: {w}")
    if p.safe:
        print("safe: yes")
    else:
        print("REFUSED:")
        for r in p.reasons:
            print(f"  - {r}")


def _plan_named_pose(args: argparse.Namespace) -> int:
    """Plan each finger of the hand (or the one named) for a pose of the pose library."""
    from utrf.poses import PoseLibrary

    hand = HandGeometry.default()
    poses = PoseLibrary.load(args.poses or (), hand=hand)
    fingers = [f for f in hand.fingers if args.finger_name in (None, f.name)]
    if not fingers:
        raise planning.PlanError(
            f"--finger-name {args.finger_name!r}: fingers are {[f.name for f in hand.fingers]}"
        )
    plans = {}
    for f in fingers:
        geom = geometry_from(args) if args.finger else f.geometry
        target = planning.named_pose_target(args.pose, f.name, poses)
        plans[f.name] = (target, _plan_one(args, geom, target))
    if args.json:
        emit({"pose": args.pose, "fingers": {n: p.to_json() for n, (_, p) in plans.items()}})
    else:
        for name, (target, p) in plans.items():
            _print_plan(p, target, f"pose {args.pose}, finger {name}")
            print()
    return 0 if all(p.safe for _, p in plans.values()) else EXIT_REFUSED


def _plan(args: argparse.Namespace) -> int:
    given = [
        n for n in ("q", "q_mm", "theta2_deg", "flexion", "tip_mm") if getattr(args, n) is not None
    ]
    if args.pose and given:
        raise planning.PlanError("give either a named POSE or one of --flexion/--theta2-deg/...")
    if args.pose:
        return _plan_named_pose(args)
    geom = geometry_from(args)
    if args.q is not None:
        target = planning.Target.q(args.q)
    elif args.q_mm is not None:
        target = planning.Target.q(args.q_mm * 1e-3)
    elif args.theta2_deg is not None:
        target = planning.Target.theta2(math.radians(args.theta2_deg))
    elif args.flexion is not None:
        target = planning.Target.flexion(args.flexion)
    elif args.tip_mm is not None:
        target = planning.Target.tip(args.tip_mm[0] * 1e-3, args.tip_mm[1] * 1e-3)
    else:
        raise planning.PlanError("give a pose: POSE, --flexion F, --theta2-deg DEG, --q Q ...")
    p = _plan_one(args, geom, target)
    if args.json:
        emit(p.to_json())
    else:
        _print_plan(p, target, f"finger {geom.source}")
    return 0 if p.safe else EXIT_REFUSED


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "kinematics", help="joint angles, tip and Jacobian of the coupled finger (Eq. 1-5)"
    )
    add_pose(p, required=True)
    add_common(p)
    p.set_defaults(handler=guarded(_kinematics))

    p = subparsers.add_parser(
        "statics", help="loaded equilibrium with elastic tendons (Sec. III, Algorithm 1)"
    )
    add_pose(p, required=False)
    add_loads(p)
    add_limits(p)
    p.add_argument("--threshold-m", type=float, default=statics.DEFAULT_THRESHOLD_M)
    p.add_argument("--max-iterations", type=int, default=statics.DEFAULT_MAX_ITERATIONS)
    p.add_argument(
        "--relaxation",
        choices=statics.RELAXATIONS,
        default=statics.DEFAULT_RELAXATION,
        help="none: the paper's plain iteration; auto: relax cases that contract slowly",
    )
    p.add_argument("--compare", action="store_true", help="also solve the other model")
    p.add_argument(
        "--verify", action="store_true", help="check against the energy minimum (serial model)"
    )
    add_common(p)
    p.set_defaults(handler=guarded(_statics))

    p = subparsers.add_parser("workspace", help="areas swept by Links 1-3 (Sec. II-C, Fig. 3)")
    p.add_argument("--out", metavar="FIG.png", help="write the figure here")
    p.add_argument(
        "--resolution-mm",
        type=float,
        default=workspace.DEFAULT_RESOLUTION_M * 1e3,
        help="raster cell width, mm",
    )
    add_common(p)
    p.set_defaults(handler=guarded(_workspace))

    p = subparsers.add_parser(
        "stiffness", help="tip deflection against payload at the straight pose (Sec. IV-A)"
    )
    p.add_argument("--out", metavar="FIG.png", help="write the figure here")
    p.add_argument(
        "--loads-kg", type=float, nargs="+", default=list(stiffness.PAPER_LOADS_KG), metavar="KG"
    )
    p.add_argument("--model", choices=(*statics.MODELS, "both"), default="both")
    p.add_argument("--no-gravity", action="store_true", help="ignore the links' own weight")
    add_pose(p, required=False)
    add_common(p)
    p.set_defaults(handler=guarded(_stiffness))

    p = subparsers.add_parser(
        "calibrate", help="fit effective parameters to measured (load, tip) data"
    )
    p.add_argument(
        "data",
        metavar="DATA.csv",
        help="load_kg, [q_m | theta2_rad], tip_x_m, tip_y_m | deflection_m",
    )
    p.add_argument(
        "--fit",
        metavar="P1,P2",
        help=f"parameters to fit, from {','.join(calibration.PARAMETERS)} (default: "
        "modulus,q_offset for tip data, modulus,tip_offset for tip data held at theta2, "
        "modulus for deflection data)",
    )
    p.add_argument("--model", choices=statics.MODELS, default=statics.DEFAULT_MODEL)
    add_common(p)
    p.set_defaults(handler=guarded(_calibrate))

    p = subparsers.add_parser(
        "plan", help="the setpoint that lands a loaded finger on a target pose, or a refusal"
    )
    p.add_argument(
        "pose",
        nargs="?",
        metavar="POSE",
        help="a named pose of the pose library (utrf poses); or give --flexion / --theta2-deg",
    )
    p.add_argument(
        "--finger-name", help="plan only this finger of a named pose (default: every finger)"
    )
    p.add_argument(
        "--poses", action="append", metavar="FILE", help="an extra pose file (repeatable)"
    )
    add_pose(p, required=False)
    add_loads(p)
    add_limits(p)
    p.add_argument("--match", choices=planning.MATCHES, default="tip")
    p.add_argument(
        "--tolerance-mm",
        type=float,
        default=planning.DEFAULT_TOLERANCE_M * 1e3,
        help="largest acceptable loaded tip error, mm",
    )
    add_common(p)
    p.set_defaults(handler=guarded(_plan))
