"""``utrf mjcf``: the hand as a MuJoCo model (MJCF), and pictures of it.

    utrf mjcf --out hand.xml                   # then: python -m mujoco.viewer --mjcf hand.xml
    utrf mjcf --render hand.png --pose fist    # a picture of a pose (off-screen, OSMesa)
    utrf mjcf --out scene.xml --object egg --object-pos-mm 60 0 70
    utrf mjcf --render poses.png --pose open fist point grasp-ball

Without ``--out`` or ``--render`` the XML goes to standard output. Exit codes: 0 done,
2 bad input (the message names it), 1 rendering impossible here.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from utrf.cli import error
from utrf.models.geometry import GeometryError, HandGeometry

EXIT_BAD_INPUT = 2
EXIT_NO_RENDER = 1


def _run(args: argparse.Namespace) -> int:
    # Imported here: mujoco loads only for this command (and picks its GL back end then).
    from utrf.models import mjcf, objects

    hand = HandGeometry.from_toml(args.hand) if args.hand else HandGeometry.default()
    layout = mjcf.load_layout(args.layout)
    xml = mjcf.hand_xml(hand, layout, drive=args.drive)
    if args.object:
        if args.object_pos_mm is None:
            raise ValueError("--object needs --object-pos-mm X Y Z (world frame, mm)")
        xml = objects.add_object(
            xml,
            objects.get_object(args.object, args.objects),
            [v * 1e-3 for v in args.object_pos_mm],
        )
    if args.out:
        Path(args.out).write_text(xml)
        print(f"wrote {args.out}: {hand.name}, drive {args.drive}", file=sys.stderr)
    if args.render:
        return _render(args, hand, xml)
    if not args.out:
        sys.stdout.write(xml)
    return 0


def _render(args: argparse.Namespace, hand: HandGeometry, xml: str) -> int:
    import matplotlib.image
    import mujoco

    from utrf.models import kinematics, mjcf, render
    from utrf.poses import PoseLibrary

    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    shots: list[tuple[str, list[float]]] = []
    if args.pose:
        library = PoseLibrary.load(args.poses or (), hand)
        shots = [(name, [float(v) for v in library[name].q(hand)]) for name in args.pose]
    else:
        q = [float(kinematics.q_from_flexion(f.geometry, args.flexion)) for f in hand.fingers]
        shots = [(f"flexion {args.flexion:g}", q)]
    images = []
    try:
        for _, q in shots:
            mjcf.set_coupled_pose(
                model, data, {f.name: v for f, v in zip(hand.fingers, q, strict=True)}, hand
            )
            images.append(render.render(model, data, height=args.height, width=args.width))
    except render.RenderError as exc:
        error("mjcf", exc)
        return EXIT_NO_RENDER
    path = Path(args.render)
    path.parent.mkdir(parents=True, exist_ok=True)
    if len(images) == 1:
        matplotlib.image.imsave(path, images[0])
    else:
        render.sheet(images, [name for name, _ in shots], path)
    print(f"wrote {path}: {', '.join(name for name, _ in shots)}", file=sys.stderr)
    return 0


def _guarded(args: argparse.Namespace) -> int:
    try:
        return _run(args)
    except (GeometryError, ValueError, OSError, KeyError) as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        error("mjcf", message)
        return EXIT_BAD_INPUT


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "mjcf",
        help="the hand as a MuJoCo model (MJCF); --render draws a pose off-screen",
        description="Write the hand's MJCF, generated from the geometry files "
        "(hand.toml, geometry/*.toml, mjcf.toml), and render poses. See docs/mujoco.md.",
    )
    p.add_argument("--out", metavar="FILE", help="write the MJCF here (default: stdout)")
    p.add_argument("--hand", metavar="FILE", help="hand TOML (default: the package's hand.toml)")
    p.add_argument("--layout", metavar="FILE", help="MJCF layout TOML (default: data/mjcf.toml)")
    p.add_argument(
        "--drive",
        choices=("duty", "force"),
        default="duty",
        help="actuators: duty = the DC motors at an H-bridge duty in [-1, 1] (default); "
        "force = motor force in N",
    )
    p.add_argument("--object", metavar="NAME", help="add an object of the library (free body)")
    p.add_argument(
        "--object-pos-mm", type=float, nargs=3, metavar=("X", "Y", "Z"), help="its position, mm"
    )
    p.add_argument("--objects", metavar="FILE", help="object library TOML (default: built-in)")
    p.add_argument("--render", metavar="PNG", help="render the hand to this PNG (off-screen)")
    pose = p.add_mutually_exclusive_group()
    pose.add_argument(
        "--pose",
        metavar="NAME",
        nargs="+",
        help="pose(s) of the pose library to render (several: one sheet, a picture each)",
    )
    pose.add_argument(
        "--flexion", type=float, default=0.0, metavar="F", help="every finger at this flexion"
    )
    p.add_argument("--poses", metavar="FILE", nargs="*", help="extra pose files")
    p.add_argument("--width", type=int, default=640, help="image width, pixels")
    p.add_argument("--height", type=int, default=480, help="image height, pixels")
    p.set_defaults(handler=_guarded)
