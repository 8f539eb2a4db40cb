"""Pictures of the hand: a pose drawn from the kinematics model at measured angles (with the
target), and the joint trajectories against their targets.

The finger chain comes from :func:`utrf.models.kinematics.joint_positions` at the tendon
displacement q = R2 · θ2 (through the coupling θ_i = q / R_i of each finger's geometry), so
what is drawn is what the model says the measured Joint-2 angle means. Drawings are in mm and
degrees, and say so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import FancyBboxPatch

from utrf.models import kinematics
from utrf.models.geometry import FingerGeometry, HandGeometry

#: Joint-2 angles, one a finger (rad)
Angles = Sequence[float] | np.ndarray
MEASURED = "#1f5fa8"
TARGET = "#d2691e"


def finger_chain(geom: FingerGeometry, theta2: float) -> np.ndarray:
    """Joint 1, 2, 3 and the tip (m), shape (4, 2), for a Joint-2 angle, through the coupling."""
    return kinematics.joint_positions(geom, kinematics.q_from_theta2(geom, theta2))


# Where each finger's Joint 1 sits on the palm in the front view (mm), and its direction.
_FRONT_BASE = {
    0: (-48.0, 25.0),
    1: (-27.0, 95.0),
    2: (-6.0, 100.0),
    3: (15.0, 95.0),
    4: (35.0, 85.0),
}
_FRONT_ANGLE = {0: 40.0}  # the thumb leans out; the others point up


def _front_segments(
    geom: FingerGeometry, theta2: float, base: tuple[float, float], lean: float
) -> np.ndarray:
    """The front view: looking at the palm, a finger shows the x-extent of its chain (flexion
    happens toward the viewer). Returns the joints' points (mm)."""
    pts = finger_chain(geom, theta2) * 1e3
    along = pts[:, 0]  # extent along the straight finger
    a = math.radians(lean)
    d = np.array([-math.sin(a), math.cos(a)])
    return np.array(base) + along[:, None] * d


def draw_pose(
    hand: HandGeometry,
    measured: Sequence[float] | np.ndarray,
    target: Sequence[float] | np.ndarray,
    path: str | Path,
    *,
    title: str,
    note: str = "",
    rendered: np.ndarray | None = None,
    labels: Mapping[str, tuple[float, float]] | None = None,
) -> Path:
    """The hand (the gesture) and a side view of each finger's chain at the measured Joint-2
    angles (solid) and the targets (dashed). Writes a PNG. ``rendered``: an image of the
    MuJoCo hand at the measured angles (``utrf.models.render.hand_at_labelled``), shown in
    place of the drawn front view, its fingers named at ``labels`` (pixels, per finger)."""
    n = len(hand.fingers)
    fig = plt.figure(figsize=(13, 9.0))
    grid = fig.add_gridspec(2, n, height_ratios=(1.7, 1.0), hspace=0.3, wspace=0.35)
    front = fig.add_subplot(grid[0, 1 : n - 1])
    if rendered is not None:
        front.imshow(rendered)
        front.axis("off")
        _label_fingers(front, rendered.shape, labels or {})
        front.set_title("the MuJoCo hand at the measured angles (rendered)", fontsize=10)
    else:
        _draw_front(front, hand, measured, target)
    _pose_panels(fig, grid, hand, measured, target)
    fig.suptitle(title, fontsize=13)
    fig.text(
        0.5,
        0.015,
        "Side views: each finger's Joints 1-3 and tip from the kinematics model "
        "(θ_i = q / R_i) at the measured Joint-2 angle (wide band) and the target (dashed); mm."
        + (f"\n{note}" if note else ""),
        ha="center",
        fontsize=8,
        color="#444444",
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _label_fingers(
    ax: Any, shape: tuple[int, ...], tips: Mapping[str, tuple[float, float]]
) -> None:
    """Each finger's name in a row under the rendered image, in the order of the fingertips
    across it, with a line to its tip: the names never overlap, however close the tips."""
    height, width = shape[0], shape[1]
    order = sorted(tips, key=lambda n: tips[n][0])
    slots = np.linspace(0.1 * width, 0.9 * width, len(order))
    for name, x in zip(order, slots, strict=True):
        ax.annotate(name, tips[name], xytext=(x, height * 1.08), textcoords="data",
                    ha="center", va="top", fontsize=9, annotation_clip=False,
                    arrowprops={"arrowstyle": "-", "lw": 0.7, "color": "#333333",
                                "shrinkA": 1, "shrinkB": 2})  # fmt: skip


def _draw_front(front: Any, hand: HandGeometry, measured: Angles, target: Angles) -> None:
    """The drawn front view (when the MuJoCo hand cannot be rendered)."""
    palm = FancyBboxPatch(
        (-62, -70), 112, 160, boxstyle="round,pad=2,rounding_size=18", fc="#f1e4d8", ec="#b09070"
    )
    front.add_patch(palm)
    for i, f in enumerate(hand.fingers):
        base = _FRONT_BASE.get(i, (-30 + 20 * i, 95.0))
        lean = _FRONT_ANGLE.get(i, 0.0)
        pts = _front_segments(f.geometry, measured[i], base, lean)
        front.plot(pts[:, 0], pts[:, 1], "-", color=MEASURED, lw=10, solid_capstyle="round")
        front.plot(pts[1:-1, 0], pts[1:-1, 1], "o", color="white", ms=2.5)  # the joints
        pts = _front_segments(f.geometry, target[i], base, lean)
        front.plot(pts[:, 0], pts[:, 1], "--", color=TARGET, lw=1.6)
        front.plot(pts[-1, 0], pts[-1, 1], "_", color=TARGET, ms=14, mew=2.5)  # target tip
        if i == 0:
            front.text(base[0] - 8, base[1] - 12, f.name, ha="right", va="top", fontsize=8)
        else:
            front.text(base[0], -64, f.name, ha="center", va="bottom", fontsize=8, rotation=90)
    front.set_aspect("equal")
    front.set_xlim(-175, 95)
    front.set_ylim(-80, 285)
    front.set_title("front view: the gesture (a flexed finger shows short)", fontsize=10)
    front.set_xlabel("mm", fontsize=8)
    front.tick_params(labelsize=7)


def _pose_panels(fig: Any, grid: Any, hand: HandGeometry, measured: Angles, target: Angles) -> None:
    """The numbers, the key and each finger's side view."""
    n = len(hand.fingers)
    # the numbers, for people: degrees
    info = fig.add_subplot(grid[0, 0])
    info.axis("off")
    lines = ["Joint-2 angle (°)", "finger   measured  target"]
    for i, f in enumerate(hand.fingers):
        lines.append(f"{f.name:<8} {math.degrees(measured[i]):7.1f} {math.degrees(target[i]):7.1f}")
    worst = max(abs(a - b) for a, b in zip(measured, target, strict=True))
    lines += ["", f"largest error {math.degrees(worst):.1f}°"]
    info.text(0.0, 0.95, "\n".join(lines), family="monospace", fontsize=9, va="top")
    key = fig.add_subplot(grid[0, n - 1])
    key.axis("off")
    key.plot([], [], "-", color=MEASURED, lw=7, alpha=0.45, label="measured")
    key.plot([], [], "--", color=TARGET, lw=1.8, label="target")
    key.legend(loc="upper left", fontsize=9, frameon=False)
    limits = _side_limits(hand, measured, target)
    for i, f in enumerate(hand.fingers):
        ax = fig.add_subplot(grid[1, i])
        _side_view(ax, f.geometry, measured[i], target[i], limits)
        m_deg, t_deg = math.degrees(measured[i]), math.degrees(target[i])
        ax.set_title(f"{f.name}\nθ2 {m_deg:.1f}° (target {t_deg:.1f}°)", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("mm", fontsize=8)


def _side_xy(g: FingerGeometry, theta2: float) -> np.ndarray:
    """A finger's joints and tip as drawn from the side (mm): pointing up (along the straight
    finger), flexing to the left."""
    pts = finger_chain(g, theta2) * 1e3
    return np.column_stack((-pts[:, 1], pts[:, 0]))


def _side_limits(hand: HandGeometry, measured: Angles, target: Angles) -> tuple[float, ...]:
    """One frame for every side view (the same scale side by side) that holds each finger
    whole at both angles, its palm too, with a margin."""
    xy = [np.array([[12.0, 0.0], [0.0, -0.6e3 * f.geometry.total_length_m]])
          for f in hand.fingers]  # fmt: skip
    for i, f in enumerate(hand.fingers):
        for value in (measured[i], target[i]):
            if math.isfinite(value):
                xy.append(_side_xy(f.geometry, value))
    allxy = np.vstack(xy)
    pad = 15.0
    lo, hi = allxy.min(axis=0) - pad, allxy.max(axis=0) + pad
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def _side_view(
    ax: Any, g: FingerGeometry, measured: float, target: float, limits: tuple[float, ...]
) -> None:
    """One finger from the side at the measured angle (a wide pale band, under) and the
    target (a dark dashed line with open joints, over it: seen where the two coincide)."""
    reach = 1e3 * g.total_length_m
    for value, color, style, width, alpha, z, label in (
        (measured, MEASURED, "-", 7.0, 0.45, 2, "measured"),
        (target, TARGET, "--", 1.8, 1.0, 3, "target"),
    ):
        xy = _side_xy(g, value)
        ax.plot(xy[:, 0], xy[:, 1], style, color=color, lw=width, alpha=alpha, zorder=z,
                label=label, solid_capstyle="round")  # fmt: skip
        ax.plot(xy[:-1, 0], xy[:-1, 1], "o", color=color, zorder=z,
                ms=6 if style == "-" else 4, mfc=color if style == "-" else "white")  # fmt: skip
    ax.plot([6, 6], [-reach * 0.6, 0], color="#b09070", lw=10, solid_capstyle="butt")  # palm
    ax.set_aspect("equal")
    ax.set_xlim(limits[0], limits[1])
    ax.set_ylim(limits[2], limits[3])


@dataclass(frozen=True)
class Segment:
    """One step of a run: a pose from board time ``start`` to ``end`` (s)."""

    name: str
    start: float
    end: float
    goal: Sequence[float]  # rad, per finger


def plot_trajectories(
    finger_names: Sequence[str],
    time_s: np.ndarray,
    measured: Mapping[str, np.ndarray],
    target: Mapping[str, np.ndarray],
    segments: Sequence[Segment],
    path: str | Path,
    *,
    title: str = "Joint-2 angles against their targets",
) -> Path:
    """Per finger: the measured Joint-2 angle, the target the board used (the streamed
    minimum-jerk path) and each pose's goal, in degrees against board time."""
    n = len(finger_names)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.9 * n + 1), sharex=True)
    axes = np.atleast_1d(axes)
    t = np.asarray(time_s) - (time_s[0] if len(time_s) else 0.0)
    t0 = time_s[0] if len(time_s) else 0.0
    for k, (ax, name) in enumerate(zip(axes, finger_names, strict=True)):
        ax.plot(t, np.degrees(target[name]), "--", color=TARGET, lw=1.4, label="target (board)")
        ax.plot(t, np.degrees(measured[name]), "-", color=MEASURED, lw=1.6, label="measured")
        for j, seg in enumerate(segments):
            ax.hlines(
                math.degrees(seg.goal[k]),
                seg.start - t0,
                seg.end - t0,
                colors="#555555",
                linestyles=":",
                lw=1.0,
                label="pose goal" if j == 0 else None,
            )
            if j % 2:
                ax.axvspan(seg.start - t0, seg.end - t0, color="#f3f3f3", zorder=0)
            if k == 0:
                ax.text(
                    (seg.start + seg.end) / 2 - t0,
                    1.02,
                    seg.name,
                    transform=ax.get_xaxis_transform(),
                    ha="center",
                    va="bottom",
                    fontsize=9,
                )
        ax.set_ylabel(f"{name}\nθ2 (°)", fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("board time (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=9, frameon=False)
    fig.suptitle(title, fontsize=12, y=0.995)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
