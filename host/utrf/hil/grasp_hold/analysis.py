"""A grasp hold's results from its files alone (``samples.csv``, ``hits.csv``, ``meta.json``):
per finger the drift, the disturbances and their recovery, faults, duties and currents, and
the tracked tip's slip. What the run and ``utrf hil analyse`` share."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import read_rows
from utrf.hand.state import fault_names
from utrf.hil.grasp_hold.config import HIT_COLUMNS, GraspHoldConfig, sample_columns
from utrf.hil.runs import write_json
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry


def read_samples(out: Path, names: list[str]) -> list[dict[str, Any]]:
    """The rows of a run's ``samples.csv``."""
    return read_rows(out / "samples.csv", sample_columns(names))


def tracker_samples(rows: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """Which rows hold a new tracker sample in view, and which repeat the previous row's
    frame: a row sampled faster than the tracker measures is not a new sample."""
    visible = np.array([int(r["visible"]) for r in rows]) == 1
    frames = np.array([int(r.get("tracker_frame", -1) or -1) for r in rows])
    repeated = np.zeros(len(rows), dtype=bool)
    repeated[1:] = (frames[1:] >= 0) & (frames[1:] == frames[:-1])
    return visible & ~repeated, repeated


def _events(
    t: np.ndarray, dev: np.ndarray, detect: float, recover: float, hold_s: float = 0.2
) -> list[dict[str, Any]]:
    """Disturbances of one finger: from the first sample beyond ``detect`` to the first after
    which the deviation stays within ``recover`` for ``hold_s``."""
    out: list[dict[str, Any]] = []
    i = 0
    n = len(t)
    while i < n:
        if abs(dev[i]) <= detect:
            i += 1
            continue
        start = i
        # back to the start of the excursion: the last sample within the recovery band
        while start > 0 and abs(dev[start - 1]) > recover:
            start -= 1
        j = i
        recovered_at = None
        while j < n:
            if abs(dev[j]) <= recover:
                k = j
                while k < n and abs(dev[k]) <= recover and t[k] - t[j] < hold_s:
                    k += 1
                if k >= n or abs(dev[k]) <= recover:
                    recovered_at = j
                    break
                j = k
            j += 1
        end = recovered_at if recovered_at is not None else n - 1
        seg = slice(start, end + 1)
        peak = int(np.argmax(np.abs(dev[seg]))) + start
        out.append(
            {
                "start_s": float(t[start]),
                "peak_s": float(t[peak]),
                "largest_deviation_rad": float(dev[peak]),
                "recovery_s": float(t[recovered_at] - t[start])
                if recovered_at is not None
                else None,
            }
        )
        i = end + 1
    return out


def analyse(
    out: Path, hand_geometry: HandGeometry | None = None, rows: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """A run's results from its files (``rows``: its samples when the caller has read them)."""
    meta = json.loads((out / "meta.json").read_text())
    config = GraspHoldConfig(**meta["config"])
    geometry = hand_geometry or HandGeometry.default()
    names = [f.name for f in geometry.fingers]
    if rows is None:
        rows = read_samples(out, names)
    if not rows:
        empty: dict[str, Any] = {
            "experiment": "grasp hold (paper Sec. IV-C)",
            "pose": config.pose,
            "planned_duration_s": config.duration_s,
            "complete": False,
            "samples": 0,
        }
        write_json(out / "results.json", empty)
        return empty
    t = np.array([float(r["time_s"]) for r in rows])
    base = t < config.baseline_s
    end = t >= t[-1] - config.baseline_s
    hits = read_rows(out / "hits.csv", HIT_COLUMNS)
    per = {}
    worst_dev, worst_rec = 0.0, 0.0
    unrecovered = 0
    for i, n in enumerate(names):
        th = np.array([float(r[f"{n}_theta2_rad"]) for r in rows])
        da = np.array([float(r[f"{n}_duty_a"]) for r in rows])
        db = np.array([float(r[f"{n}_duty_b"]) for r in rows])
        cur = np.array([float(r[f"{n}_current_a_a"]) for r in rows])
        faults = sorted({int(r[f"{n}_faults"]) for r in rows} - {0})
        th0 = float(th[base].mean()) if base.any() else float(th[0])
        th1 = float(th[end].mean())
        g = geometry.fingers[i].geometry
        tip0 = kinematics.tip_position(g, kinematics.q_from_theta2(g, th0))
        tip1 = kinematics.tip_position(g, kinematics.q_from_theta2(g, th1))
        dev = th - th0
        events = _events(t, dev, config.detect_rad, config.recovery_rad)
        for e in events:
            worst_dev = max(worst_dev, abs(e["largest_deviation_rad"]))
            if e["recovery_s"] is None:
                unrecovered += 1
            else:
                worst_rec = max(worst_rec, e["recovery_s"])
        per[n] = {
            "baseline_theta2_rad": th0,
            "end_theta2_rad": th1,
            "drift_rad": th1 - th0,
            "tip_drift_m": float(np.hypot(*(tip1 - tip0))),
            "largest_deviation_rad": float(dev[np.argmax(np.abs(dev))]),
            "disturbances": events,
            "faults": [fault_names(f) for f in faults],
            "modes": sorted({str(r[f"{n}_mode"]) for r in rows}),
            "duty_a": {"mean": float(np.nanmean(da)), "max": float(np.nanmax(da))},
            "duty_b": {"mean": float(np.nanmean(db)), "max": float(np.nanmax(db))},
            "current_a_a": (
                {"mean": float(np.nanmean(cur)), "max": float(np.nanmax(cur))}
                if np.isfinite(cur).any()
                else None
            ),
        }
    vis, repeated = tracker_samples(rows)
    raw = np.array([[float(r[c]) for c in ("raw_x_m", "raw_y_m", "raw_z_m")] for r in rows])
    slip = None
    if (vis & base).any() and (vis & end).any():
        slip = float(np.linalg.norm(raw[vis & end].mean(axis=0) - raw[vis & base].mean(axis=0)))
    result: dict[str, Any] = {
        "experiment": "grasp hold (paper Sec. IV-C)",
        "pose": config.pose,
        "duration_s": float(t[-1]),
        "planned_duration_s": config.duration_s,
        "complete": bool(t[-1] >= config.duration_s - 2.0 / config.sample_hz),
        "samples": len(rows),
        "tracker_repeated_frames": int(repeated.sum()),
        "emulated": config.emulated,
        "hits_applied": [
            {
                "time_s": float(h["time_s"]),
                "finger": names[int(h["finger"])],
                "impulse_ns": [float(h["impulse_x_ns"]), float(h["impulse_y_ns"])],
            }
            for h in hits
        ],
        "tracked_finger": names[config.tracked_finger],
        "tracked_tip_slip_m": slip,
        "largest_deviation_rad": worst_dev,
        "longest_recovery_s": worst_rec,
        "unrecovered_disturbances": unrecovered,
        "faults": {n: p["faults"] for n, p in per.items() if p["faults"]},
        "fingers": per,
        "thresholds": {"detect_rad": config.detect_rad, "recovery_rad": config.recovery_rad},
    }
    write_json(out / "results.json", result)
    return result
