"""Off-screen pictures of the MuJoCo hand, with software OpenGL (OSMesa) when there is no
display.

``render(model, data)`` returns an RGB image (height, width, 3) of uint8; ``render_png``
writes one. The OpenGL context comes from ``MUJOCO_GL`` when it is set (``osmesa``, ``egl``,
``glfw``), otherwise OSMesa without a display (Debian's ``libosmesa6``, installed by
tools/setup.sh) and GLFW with one. The context is chosen here, per call, not by MuJoCo at its
first import, so it works whichever module imported mujoco first; it is freed before
returning (left to the interpreter's shutdown, MuJoCo's contexts print ctypes errors).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.image
import mujoco
import numpy as np

from utrf.models.geometry import HandGeometry

DEFAULT_SIZE = (480, 640)  # height, width (pixels)


class RenderError(RuntimeError):
    """No OpenGL context for off-screen rendering; the message says what to install or set."""


def gl_backend() -> str:
    """The OpenGL back end ``render`` uses: MUJOCO_GL, else osmesa without a display."""
    chosen = os.environ.get("MUJOCO_GL", "").strip().lower()
    if chosen:
        return chosen
    has_display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    return "glfw" if has_display else "osmesa"


def _context_class() -> Any:
    backend = gl_backend()
    try:
        if backend == "osmesa":
            from mujoco.osmesa import GLContext
        elif backend == "egl":
            from mujoco.egl import GLContext
        elif backend == "glfw":
            from mujoco.glfw import GLContext
        else:
            raise RenderError(f"MUJOCO_GL={backend!r}: use osmesa, egl or glfw")
    except ImportError as exc:
        raise RenderError(
            f"cannot load the {backend} OpenGL back end ({exc}); for software rendering "
            "install Debian's libosmesa6 (tools/setup.sh) and use MUJOCO_GL=osmesa"
        ) from exc
    return GLContext


def hand_camera(
    lookat: tuple[float, float, float] = (0.03, 0.0, 0.04),
    distance_m: float = 0.40,
    azimuth_deg: float = 140.0,
    elevation_deg: float = -32.0,
) -> mujoco.MjvCamera:
    """A free camera looking at the hand from in front, on the thumb's side, above the palm."""
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = lookat
    cam.distance = distance_m
    cam.azimuth = azimuth_deg
    cam.elevation = elevation_deg
    return cam


def render(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    *,
    height: int = DEFAULT_SIZE[0],
    width: int = DEFAULT_SIZE[1],
    camera: mujoco.MjvCamera | None = None,
) -> np.ndarray:
    """The scene as an RGB image, shape (height, width, 3), uint8."""
    if not (0 < width <= model.vis.global_.offwidth and 0 < height <= model.vis.global_.offheight):
        raise RenderError(
            f"image {width}x{height} is larger than the model's off-screen buffer "
            f"{model.vis.global_.offwidth}x{model.vis.global_.offheight} (<visual><global>)"
        )
    context_class = _context_class()
    try:
        gl = context_class(width, height)
        gl.make_current()
    except Exception as exc:  # each back end fails its own way (ctypes, GLFW, EGL errors)
        raise RenderError(
            f"cannot open a {gl_backend()} OpenGL context ({exc}); for software rendering "
            "install Debian's libosmesa6 (tools/setup.sh) and use MUJOCO_GL=osmesa"
        ) from exc
    context = None
    try:
        context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, context)
        scene = mujoco.MjvScene(model, maxgeom=2000)
        mujoco.mjv_updateScene(
            model,
            data,
            mujoco.MjvOption(),
            mujoco.MjvPerturb(),
            camera if camera is not None else hand_camera(),
            mujoco.mjtCatBit.mjCAT_ALL,
            scene,
        )
        viewport = mujoco.MjrRect(0, 0, width, height)
        mujoco.mjr_render(viewport, scene, context)
        rgb = np.empty((height, width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(rgb, None, viewport, context)
        return np.flipud(rgb).copy()  # OpenGL's rows run bottom-up
    finally:
        if context is not None:
            context.free()
        gl.free()


def hand_at(
    theta2: Sequence[float],
    hand: HandGeometry | None = None,
    *,
    height: int = DEFAULT_SIZE[0],
    width: int = DEFAULT_SIZE[1],
    camera: mujoco.MjvCamera | None = None,
) -> np.ndarray:
    """The MuJoCo hand (``mjcf.hand_xml``) with each finger at a Joint-2 angle (rad, on the
    rigid coupling), rendered: an RGB image as ``render`` gives. The default camera is
    ``pose_camera`` moved back until every finger is in the frame (``framed_camera``)."""
    return hand_at_labelled(theta2, hand, height=height, width=width, camera=camera)[0]


def hand_at_labelled(
    theta2: Sequence[float],
    hand: HandGeometry | None = None,
    *,
    height: int = DEFAULT_SIZE[0],
    width: int = DEFAULT_SIZE[1],
    camera: mujoco.MjvCamera | None = None,
) -> tuple[np.ndarray, dict[str, tuple[float, float]]]:
    """``hand_at``'s image and where each fingertip is in it (pixels: column, row), for the
    fingers' labels."""
    from utrf.models import mjcf

    hand = hand if hand is not None else HandGeometry.default()
    if len(theta2) != len(hand.fingers):
        raise ValueError(f"need {len(hand.fingers)} Joint-2 angles, got {len(theta2)}")
    model = mujoco.MjModel.from_xml_string(mjcf.hand_xml(hand))
    data = mujoco.MjData(model)
    q = {}
    for f, angle in zip(hand.fingers, theta2, strict=True):
        lo, hi = f.geometry.q_range_m
        q[f.name] = min(max(float(angle) * f.geometry.guide_radii_m[1], lo), hi)
    mjcf.set_coupled_pose(model, data, q, hand)
    if camera is None:
        camera = framed_camera(model, data, pose_camera(), height=height, width=width)
    tips = np.array([data.site(f"{f.name}_tip").xpos for f in hand.fingers])
    px = project(model, data, tips, camera, height=height, width=width)
    image = render(model, data, height=height, width=width, camera=camera)
    return image, {f.name: (float(c), float(r)) for f, (c, r) in zip(hand.fingers, px, strict=True)}


def pose_camera() -> mujoco.MjvCamera:
    """A camera for a gesture: over the palm, on the thumb's side, the fingertips in front."""
    return hand_camera(lookat=(0.02, 0.0, 0.05), distance_m=0.32, azimuth_deg=150.0,
                       elevation_deg=-35.0)  # fmt: skip


def project(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    points: np.ndarray,
    camera: mujoco.MjvCamera,
    *,
    height: int = DEFAULT_SIZE[0],
    width: int = DEFAULT_SIZE[1],
) -> np.ndarray:
    """World points (n, 3) as pixels (column, row) of ``render``'s image with this camera
    (MuJoCo's perspective: its frustum, the width following the image's aspect); a point
    behind the camera gets NaN."""
    scene = mujoco.MjvScene(model, maxgeom=1)
    mujoco.mjv_updateCamera(model, data, camera, scene)
    # the scene holds two eyes an inter-pupillary distance apart; mjr_render views from
    # their average
    cam = mujoco.mjv_averageCamera(scene.camera[0], scene.camera[1])
    forward, up = np.array(cam.forward), np.array(cam.up)
    right = np.cross(forward, up)
    v = np.atleast_2d(points) - np.array(cam.pos)
    depth = v @ forward
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = np.where(depth > 0, (v @ right) / depth * cam.frustum_near, np.nan)
        ys = np.where(depth > 0, (v @ up) / depth * cam.frustum_near, np.nan)
    span = cam.frustum_top - cam.frustum_bottom
    half_w = cam.frustum_width or 0.5 * width / height * span
    col = (xs - (cam.frustum_center - half_w)) / (2 * half_w) * width
    row = (cam.frustum_top - ys) / span * height
    return np.column_stack((col, row))


def framed_camera(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    camera: mujoco.MjvCamera,
    *,
    height: int = DEFAULT_SIZE[0],
    width: int = DEFAULT_SIZE[1],
    margin: float = 0.06,
) -> mujoco.MjvCamera:
    """``camera`` aimed at the middle of the model's bodies and moved along its line of sight
    until all of them, and every site (the fingertips), lie ``margin`` (a fraction of the
    image) inside the frame: a straight finger is not cropped."""
    pts = np.vstack((data.xpos[1:], data.site_xpos))
    camera.lookat[:] = (pts.min(axis=0) + pts.max(axis=0)) / 2
    camera.distance *= 0.6  # from nearer than asked: the hand fills the frame
    lo = np.array([margin * width, margin * height])
    hi = np.array([(1 - margin) * width, (1 - margin) * height])
    for _ in range(40):
        px = project(model, data, pts, camera, height=height, width=width)
        if np.isfinite(px).all() and (px >= lo).all() and (px <= hi).all():
            break
        camera.distance *= 1.08
    return camera


def render_png(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    path: str | Path,
    **kwargs: Any,
) -> Path:
    """Render (``render``'s keyword arguments) and write a PNG; returns its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(path, render(model, data, **kwargs))
    return path


def sheet(images: list[np.ndarray], titles: list[str], path: str | Path, columns: int = 2) -> Path:
    """Pictures side by side with their titles, as one PNG (matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if len(images) != len(titles) or not images:
        raise ValueError("sheet needs one title per picture, and at least one picture")
    rows = -(-len(images) // columns)
    h, w = images[0].shape[:2]
    fig, axes = plt.subplots(rows, columns, figsize=(columns * w / 100, rows * (h + 30) / 100))
    for ax in np.ravel(axes):
        ax.axis("off")
    for ax, image, title in zip(np.ravel(axes), images, titles, strict=False):
        ax.imshow(image)
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
