"""A grasp hold's results for people: the figure and the table (degrees and mm, says so).
:func:`write` analyses a run's files and writes its results and figure: what the run's command
and ``utrf hil analyse`` print."""

from __future__ import annotations

import math
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from utrf.hil.grasp_hold.analysis import (
    Samples,
    analyse,
    parse_samples,
    read_samples,
    tracker_samples,
)
from utrf.models.geometry import HandGeometry

FIGURE = "grasp_hold.png"
SIZE_IN, DPI = (7.5, 7.5), 110  # the figure's size (in) and resolution (dots per inch)


def write(
    out: Path, hand_geometry: HandGeometry | None = None, lines: Sequence[str] | None = None
) -> dict[str, Any]:
    """The run's results (``results.json``) and its figure, from its files alone; ``lines``:
    the rows of ``samples.csv`` the run wrote, kept (``run.run``'s): the same samples, not
    read back."""
    names = [f.name for f in (hand_geometry or HandGeometry.default()).fingers]
    samples = None
    if lines is not None:
        samples = parse_samples(lines, names)
    elif (out / "meta.json").exists():
        samples = read_samples(out, names)  # read once, for the analysis and the figure
    result = analyse(out, hand_geometry, samples)
    if result["samples"] and samples is not None:
        plot(result, samples, list(result["fingers"]), out / FIGURE)
    return result


def preload_plotting() -> threading.Thread:
    """Import matplotlib (about a second of CPU, most of the figure's cost) on a thread of its
    own while the run goes on: the run's thread spends its time in the harness, outside the
    interpreter. While it imports, the interpreter hands over every 0.1 ms (not 5), so the
    run's thread, back from the harness, does not wait for it."""
    thread = threading.Thread(target=_import_plotting, name="utrf-import-matplotlib", daemon=True)
    thread.start()
    return thread


def _import_plotting() -> None:
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot
    except Exception:  # plot() imports it again and says what is wrong
        pass
    finally:
        sys.setswitchinterval(interval)


def _running_mean(t: np.ndarray, y: np.ndarray, window_s: float) -> np.ndarray:
    """Mean of ``y`` over the trailing ``window_s`` at each sample (NaNs skipped)."""
    ok = np.isfinite(y)
    c = np.concatenate(([0.0], np.cumsum(np.where(ok, y, 0.0))))
    n = np.concatenate(([0], np.cumsum(ok)))
    lo = np.searchsorted(t, t - window_s, side="left")
    hi = np.arange(1, len(t) + 1)
    count = n[hi] - n[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, (c[hi] - c[lo]) / np.maximum(count, 1), np.nan)


def decimate(x: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """The points of a line (``x`` rising) a plot ``columns`` pixels wide shows: in each
    column of ``x`` its lowest and highest ``y`` (in their order), so every extreme stays; a
    column with no finite ``y`` keeps one NaN (the line's gap). Short lines stay whole."""
    if len(x) <= 2 * columns or not x[-1] > x[0]:
        return x, y
    col = np.minimum(((x - x[0]) * (columns / (x[-1] - x[0]))).astype(np.int64), columns - 1)
    finite = np.isfinite(y)
    lowest = np.lexsort((np.where(finite, y, np.inf), col))  # by column, then y rising
    highest = np.lexsort((np.where(finite, -y, np.inf), col))  # by column, then y falling
    first = np.flatnonzero(np.r_[True, col[lowest][1:] != col[lowest][:-1]])
    keep = np.union1d(lowest[first], highest[first])  # sorted: the line's order
    return x[keep], y[keep]


def plot(result: dict[str, Any], samples: Samples, names: list[str], path: Path) -> Path:
    """What the run concludes: each finger's drift (Joint 2 averaged over 1 s outside its
    disturbances, so the drift shows under the readings' noise; the drift from the baseline to
    the end window in the legend), each disturbance's deviation and recovery time, and the
    tracked tip's displacement from its baseline (1 s means of the tracker's new frames)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = samples["time_s"]
    fig, ax = plt.subplots(3, 1, figsize=SIZE_IN, sharex=True)
    # each line at most two points a pixel column: the same picture as every sample's point
    columns = round(SIZE_IN[0] * DPI)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, n in enumerate(names):
        p = result["fingers"][n]
        c = colours[k % len(colours)]
        # the disturbances are the middle panel's: left out of the drift
        held = samples[f"{n}_theta2_rad"].copy()
        for e in p["disturbances"]:
            stop = e["start_s"] + (e["recovery_s"] if e["recovery_s"] is not None else np.inf)
            held[(t >= e["start_s"]) & (t <= stop)] = np.nan
        dev = np.degrees(_running_mean(t, held, 1.0) - p["baseline_theta2_rad"])
        ax[0].plot(*decimate(t, dev, columns), lw=0.9, color=c,
                   label=f"{n}: drift {math.degrees(p['drift_rad']):+.2f} deg")  # fmt: skip
        for e in p["disturbances"]:
            peak = math.degrees(e["largest_deviation_rad"])
            rec = e["recovery_s"]
            end = e["start_s"] + (rec if rec is not None else t[-1] - e["start_s"])
            ax[1].plot([e["start_s"], end], [peak, peak], color=c, lw=2.0, alpha=0.6)
            ax[1].plot([e["peak_s"]], [peak], "o", color=c, ms=4)
            ax[1].annotate(f"{rec:.2f} s" if rec is not None else "not recovered",
                           (e["start_s"], peak), fontsize=6, xytext=(3, 3),
                           textcoords="offset points")  # fmt: skip
    for h in result["hits_applied"]:
        for a in ax:
            a.axvline(h["time_s"], color="k", lw=0.5, alpha=0.3)
    ax[0].axhline(0.0, color="k", lw=0.5)
    ax[0].set_ylabel("Joint 2 from baseline,\n1 s mean, held (deg)")
    ax[0].legend(fontsize=6, ncol=3)
    ax[1].axhline(0.0, color="k", lw=0.5)
    ax[1].set_ylabel("disturbance: largest\ndeviation (deg)")
    ax[1].set_title("bars: from the disturbance to its recovery (time written); grey: hits",
                    fontsize=7)  # fmt: skip
    vis, _ = tracker_samples(samples)
    raw = np.column_stack([samples[c] for c in ("raw_x_m", "raw_y_m", "raw_z_m")])
    base = vis & (t < t[0] + 1.0)
    if base.any():
        # The 1 s mean position's distance from the baseline's: the norm of each noisy
        # sample would sit at the noise's size, not at the tip's movement.
        mean_xyz = np.column_stack([_running_mean(t[vis], raw[vis, k], 1.0) for k in range(3)])
        moved = np.linalg.norm(mean_xyz - raw[base].mean(axis=0), axis=1) * 1e3
        ax[2].plot(*decimate(t[vis], moved, columns), lw=1.0, color="C3", label="1 s mean")
        ax[2].legend(fontsize=6)
    slip = result.get("tracked_tip_slip_m")
    ax[2].set_ylabel(f"tracked tip ({result['tracked_finger']})\nfrom baseline (mm)")
    ax[2].set_title(
        "tracked tip: "
        + (f"moved {slip * 1e3:.2f} mm, baseline to end" if slip is not None else "not seen"),
        fontsize=7,
    )
    ax[2].set_xlabel("time into the hold (s)")
    ax[0].set_title(
        f"Grasp hold {result['pose']}: largest deviation "
        f"{math.degrees(result['largest_deviation_rad']):.1f} deg, longest recovery "
        f"{result['longest_recovery_s']:.2f} s",
        fontsize=9,
    )
    for a in ax:
        a.grid(alpha=0.3)
    # fixed margins that fit the labels: tight_layout drew the figure once more to find them
    # (a third of the figure's cost)
    fig.subplots_adjust(left=0.12, right=0.98, top=0.955, bottom=0.065, hspace=0.22)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def describe(result: dict[str, Any]) -> str:
    lines = [
        f"grasp hold {result.get('pose')}: {result.get('duration_s', 0):.1f} s of "
        f"{result.get('planned_duration_s', 0):g} s, {len(result.get('hits_applied', []))} "
        "emulated hits",
        "finger   drift (deg)  tip drift (mm)  largest dev (deg)  disturbances  longest "
        "recovery (s)  duty A mean/max  faults",
    ]
    for n, p in result.get("fingers", {}).items():
        recs = [e["recovery_s"] for e in p["disturbances"] if e["recovery_s"] is not None]
        lines.append(
            f"{n:8s} {math.degrees(p['drift_rad']):+9.2f}  {p['tip_drift_m'] * 1e3:12.2f}  "
            f"{math.degrees(p['largest_deviation_rad']):+15.2f}  {len(p['disturbances']):12d}  "
            f"{max(recs) if recs else 0:20.2f}  {p['duty_a']['mean']:.2f}/{p['duty_a']['max']:.2f}"
            f"        {','.join(p['faults']) or 'none'}"
        )
    if result.get("tracked_tip_slip_m") is not None:
        lines.append(
            f"tracked tip ({result['tracked_finger']}) moved "
            f"{result['tracked_tip_slip_m'] * 1e3:.2f} mm from the baseline to the end of the "
            "hold (tracker)"
        )
    return "\n".join(lines)
