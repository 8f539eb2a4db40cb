"""An object hold's results for people (``utrf hil grasp-hold --emulated --object``): the
figure, the render of the hand holding the object beside the object's displacement, its slip
and each finger's contact force over the hold. :func:`write` analyses a run's files and writes
its results and figure: what the run's command and ``utrf hil analyse`` print."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from utrf.hil import object_hold as oh
from utrf.hil.runs import write_json

FIGURE = "object_hold.png"


def write(out: Path, *, figure: bool = True) -> dict[str, Any]:
    """The run's results (``results.json``) and its figure (unless ``figure`` is False), from
    its files alone."""
    result = oh.analyse(out)
    render = out / oh.RENDER
    result["render"] = str(render) if render.exists() else None
    drawn = figure and result["samples"]
    result["figure"] = str(plot(out, result, out / FIGURE)) if drawn else None
    write_json(out / "results.json", result)
    return result


def settled(t: np.ndarray, d: np.ndarray, window_s: float) -> np.ndarray:
    """The trailing median of ``d`` over ``window_s`` at each sample: the displacement with a
    hit's swing taken out, i.e. what the object has slipped so far."""
    lo = np.searchsorted(t, t - window_s, side="left")
    return np.array([np.median(d[a : i + 1]) for i, a in enumerate(lo)])


def plot(out: Path, result: dict[str, Any], path: Path) -> Path:
    """The render (left, when the run made one) beside three panels over time: the object's
    displacement from the hold's baseline (and its x, y, z), its slip (the 1 s trailing
    median of the displacement: what stays once a hit has passed), each finger's contact
    force on it (the breaking force dashed for a fragile object). Hits: grey lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image
    import matplotlib.pyplot as plt

    meta_config = oh.ObjectHoldConfig(**_config(out))
    rows = oh._read(out / "object_samples.csv", oh.SAMPLE_COLUMNS)
    t = rows["time_s"]
    pos = np.column_stack((rows["x_m"], rows["y_m"], rows["z_m"]))
    free = rows["phase"] != "close"
    ref = pos[free][0] if free.any() else pos[0]
    base = oh.baseline_position(t, pos, meta_config.baseline_s, ref)
    held = t >= 0
    th, d_xyz = t[held], (pos[held] - base) * 1e3
    disp = np.linalg.norm(d_xyz, axis=1)
    render = out / oh.RENDER
    fig = plt.figure(figsize=(12.5, 6.2) if render.exists() else (7.5, 6.2))
    grid = fig.add_gridspec(3, 2 if render.exists() else 1,
                            width_ratios=[1.1, 1.0] if render.exists() else None)  # fmt: skip
    col = 1 if render.exists() else 0
    if render.exists():
        ax_img = fig.add_subplot(grid[:, 0])
        ax_img.imshow(matplotlib.image.imread(render))
        ax_img.set_axis_off()
        ax_img.set_title(f"the {result['object']} in the hand, closed ({result['pose']})",
                         fontsize=9)  # fmt: skip
    ax = [fig.add_subplot(grid[0, col])]
    ax += [fig.add_subplot(grid[k, col], sharex=ax[0]) for k in (1, 2)]
    for k, axis in enumerate("xyz"):
        ax[0].plot(th, d_xyz[:, k], lw=0.8, ls="--", alpha=0.7, label=axis)
    ax[0].plot(th, disp, color="k", lw=1.0, label="|d|")
    ax[0].set_ylabel("displacement from\nbaseline (mm)")
    ax[0].legend(fontsize=6, ncol=4)
    slip = settled(th, disp, 1.0) if len(th) else disp
    ax[1].plot(th, slip, color="C3", lw=1.2)
    last = result["slip_mm"]
    ax[1].set_ylabel("slip (mm,\n1 s median of |d|)")
    ax[1].set_title(f"slip at the end {last:.2f} mm" if last is not None else "", fontsize=7)
    for n in oh.FINGERS:
        ax[2].plot(th, rows[f"force_{n}_n"][held], lw=0.9, label=n)
    if result["breaking_force_n"] is not None:
        ax[2].axhline(result["breaking_force_n"], color="r", ls="--", lw=0.8,
                      label=f"breaks at {result['breaking_force_n']:g} N")  # fmt: skip
    ax[2].set_ylabel("contact force (N)")
    ax[2].set_xlabel("time into the hold (s)")
    ax[2].legend(fontsize=6, ncol=3)
    for h in result["hits"]:
        for a in ax:
            a.axvline(h["time_s"], color="k", lw=0.5, alpha=0.3)
    state = f"DROPPED at {result['dropped_at_s']:.2f} s" if result["dropped"] else "held"
    ax[0].set_title(f"Object hold, the {result['object']}: {state}, "
                    f"{len(result['hits'])} hits (grey)", fontsize=9)  # fmt: skip
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _config(out: Path) -> dict[str, Any]:
    import json

    return dict(json.loads((out / "meta.json").read_text())["config"])
