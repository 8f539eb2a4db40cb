"""A grasp hold's results from its files alone (``samples.csv``, ``hits.csv``, ``meta.json``):
per finger the drift, the disturbances and their recovery, faults, duties and currents, and
the tracked tip's slip. What the run and ``utrf hil analyse`` share."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import LogFormatError, read_rows
from utrf.hand.state import fault_names
from utrf.hil.grasp_hold.config import HIT_COLUMNS, GraspHoldConfig, sample_columns
from utrf.hil.runs import write_json
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry

#: a run's samples by column (``samples.csv``'s): numbers as float, the phase and the modes as
#: text, one entry a row
Samples = dict[str, np.ndarray]


def _is_text(column: str) -> bool:
    return column == "phase" or column.endswith("_mode")


def parse_samples(lines: Sequence[str], names: list[str], source: str = "samples") -> Samples:
    """The columns of ``samples.csv``'s rows as written (``sample_line``: one line each,
    newline-ended); a line cut short (a kill) or of another width is left out, as
    :func:`~utrf.datalog.read_log` leaves it. A number column holding text is an error that
    names it."""
    columns = sample_columns(names)
    cells = [line.split(",") for line in lines if line.endswith("\n")]
    cells = [c for c in cells if len(c) == len(columns)]
    by_column = list(zip(*cells, strict=True)) or [()] * len(columns)
    out: Samples = {}
    for c, values in zip(columns, by_column, strict=True):
        if _is_text(c):
            out[c] = np.array([v.strip() for v in values], dtype=str)
            continue
        try:
            out[c] = np.array(values, dtype=float)
        except ValueError:
            bad = next(i for i, v in enumerate(values) if not _number(v))
            raise LogFormatError(
                f"{source}: column {c!r}, row {bad + 1}: {values[bad].strip()!r} is not a number"
            ) from None
    return out


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_samples(out: Path, names: list[str]) -> Samples:
    """A run's ``samples.csv`` by column (none when it is missing or its header was cut short:
    a kill before the first row; a header of other columns is an error)."""
    path = out / "samples.csv"
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    header, newline, rest = text.partition("\n")
    if newline and tuple(header.split(",")) != tuple(sample_columns(names)):
        raise LogFormatError(
            f"{path}: columns are {header.split(',')}, expected {sample_columns(names)}"
        )
    return parse_samples(rest.splitlines(keepends=True), names, str(path))


def count(samples: Samples) -> int:
    return len(samples["time_s"])


def tracker_samples(samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """Which rows hold a new tracker sample in view, and which repeat the previous row's
    frame: a row sampled faster than the tracker measures is not a new sample."""
    visible = samples["visible"] == 1
    frames = np.nan_to_num(samples["tracker_frame"], nan=-1.0)
    repeated = np.zeros(len(frames), dtype=bool)
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
    out: Path, hand_geometry: HandGeometry | None = None, samples: Samples | None = None
) -> dict[str, Any]:
    """A run's results from its files (``samples``: its samples when the caller has them, as
    :func:`read_samples` would read them: the run's own lines, :func:`parse_samples`)."""
    meta = json.loads((out / "meta.json").read_text())
    config = GraspHoldConfig(**meta["config"])
    geometry = hand_geometry or HandGeometry.default()
    names = [f.name for f in geometry.fingers]
    if samples is None:
        samples = read_samples(out, names)
    if not count(samples):
        empty: dict[str, Any] = {
            "experiment": "grasp hold (paper Sec. IV-C)",
            "pose": config.pose,
            "planned_duration_s": config.duration_s,
            "complete": False,
            "samples": 0,
        }
        write_json(out / "results.json", empty)
        return empty
    t = samples["time_s"]
    base = t < config.baseline_s
    end = t >= t[-1] - config.baseline_s
    hits = read_rows(out / "hits.csv", HIT_COLUMNS)
    per = {}
    worst_dev, worst_rec = 0.0, 0.0
    unrecovered = 0
    for i, n in enumerate(names):
        th = samples[f"{n}_theta2_rad"]
        da, db = samples[f"{n}_duty_a"], samples[f"{n}_duty_b"]
        cur = samples[f"{n}_current_a_a"]
        codes = samples[f"{n}_faults"]
        faults = sorted({int(f) for f in np.unique(codes[np.isfinite(codes)])} - {0})
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
            "modes": sorted(str(v) for v in np.unique(samples[f"{n}_mode"])),
            "duty_a": {"mean": float(np.nanmean(da)), "max": float(np.nanmax(da))},
            "duty_b": {"mean": float(np.nanmean(db)), "max": float(np.nanmax(db))},
            "current_a_a": (
                {"mean": float(np.nanmean(cur)), "max": float(np.nanmax(cur))}
                if np.isfinite(cur).any()
                else None
            ),
        }
    vis, repeated = tracker_samples(samples)
    raw = np.column_stack([samples[c] for c in ("raw_x_m", "raw_y_m", "raw_z_m")])
    slip = None
    if (vis & base).any() and (vis & end).any():
        slip = float(np.linalg.norm(raw[vis & end].mean(axis=0) - raw[vis & base].mean(axis=0)))
    result: dict[str, Any] = {
        "experiment": "grasp hold (paper Sec. IV-C)",
        "pose": config.pose,
        "duration_s": float(t[-1]),
        "planned_duration_s": config.duration_s,
        "complete": bool(t[-1] >= config.duration_s - 2.0 / config.sample_hz),
        "samples": count(samples),
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
