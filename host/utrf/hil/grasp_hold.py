"""The grasp hold (paper Sec. IV-C): a grasp pose held for a long time (the paper: 10 minutes)
while hammer hits disturb it.

The hand closes on the object with a grasp pose of the library (GRASP mode with the pose's
effort: each closing finger pushes with at most that duty and holds on contact), then holds.
On the emulated bench the object is a set of obstacles that stop the closing fingers part of
their way (``contact_fraction``), and seeded hammer hits (force pulses at the fingertips) come
at random times; on the real bench the operator hits and the run only records.

Everything is logged as it is taken (append-safe): ``samples.csv`` (every finger's Joint-2
angle, target, duties, faults and, emulated, motor currents, with the tracker's reading of the
tracked fingertip), ``hits.csv`` (the emulated hits), ``telemetry.csv`` (the Hand's stream).
:func:`analyse` works from those files alone: per finger the drift (slip) over the hold, the
largest deviation, the disturbances found in the data with their largest deviation and
recovery time, faults, and duty and current statistics.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import CsvLog, read_log
from utrf.hand.state import fault_names
from utrf.hil.bench import Bench, ProgressFn
from utrf.hil.static_loading import RunError, RunStopped, _write_json
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry

FINGER_FIELDS = ("theta2_rad", "target_rad", "duty_a", "duty_b", "mode", "faults", "current_a_a")
HIT_COLUMNS = ("time_s", "finger", "impulse_x_ns", "impulse_y_ns", "duration_s")


def sample_columns(names: list[str]) -> list[str]:
    cols = ["time_s", "phase", "raw_x_m", "raw_y_m", "raw_z_m", "visible", "tracker_frame"]
    for n in names:
        cols += [f"{n}_{f}" for f in FINGER_FIELDS]
    return cols


@dataclass(frozen=True)
class GraspHoldConfig:
    pose: str = "grasp-bottle"
    duration_s: float = 600.0
    hits: int = 20  # emulated: hammer hits spread over the hold
    hit_impulse_n_s: float = 0.3  # emulated: each hit's impulse, newton-seconds (N·s)
    hit_duration_s: float = 5e-3
    contact_fraction: float = 0.6  # emulated: the object stops closing fingers there
    tracked_finger: int = 1
    sample_hz: float = 50.0
    baseline_s: float = 1.0
    detect_rad: float = 0.02  # a disturbance: a finger this far off its baseline
    recovery_rad: float = 0.012  # recovered: back within this (about 1.5 ADC counts)
    emulated: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.duration_s) and self.duration_s >= 2 * self.baseline_s):
            raise RunError(
                f"duration_s must be at least twice baseline_s ({2 * self.baseline_s:g} s), "
                f"got {self.duration_s}"
            )
        if not 0 <= self.hits <= 10_000:
            raise RunError(f"hits must be 0..10000, got {self.hits}")
        if self.hits and self.duration_s < 2 * self.baseline_s + 1.0:
            raise RunError(
                f"hits need a hold of at least {2 * self.baseline_s + 1.0:g} s (two baselines "
                f"and time to recover), got {self.duration_s:g} s"
            )
        if not (math.isfinite(self.hit_impulse_n_s) and 0 <= self.hit_impulse_n_s <= 5):
            raise RunError(f"hit_impulse_n_s must lie in [0, 5] N s, got {self.hit_impulse_n_s}")
        if not 0.1 <= self.contact_fraction <= 1.0:
            raise RunError(f"contact_fraction must lie in [0.1, 1], got {self.contact_fraction}")
        if not 0 <= self.tracked_finger <= 4:
            raise RunError(f"tracked_finger must be 0..4, got {self.tracked_finger}")
        if not 5 <= self.sample_hz <= 500:
            raise RunError(f"sample_hz must lie in [5, 500], got {self.sample_hz}")
        if not 0 < self.recovery_rad < self.detect_rad:
            raise RunError("recovery_rad must be > 0 and below detect_rad")

    def hit_plan(
        self, closing: list[int], opening: dict[int, np.ndarray]
    ) -> list[tuple[float, int, tuple[float, float]]]:
        """Seeded hits: (time into the hold, finger, impulse) spread over the hold between its
        baseline and its end window, each within ±45° of the direction that opens its
        finger (``opening``: unit vectors, finger frame)."""
        if not self.hits or not closing:
            return []
        rng = np.random.default_rng(self.seed + 104729)
        lo, hi = self.baseline_s + 0.1, self.duration_s - self.baseline_s - 0.5
        edges = np.linspace(lo, hi, self.hits + 1)
        slots = edges[:-1] + np.diff(edges) * rng.uniform(0.1, 0.6, self.hits)
        out = []
        for t in slots:
            f = int(rng.choice(closing))
            u = opening[f]
            a = math.atan2(u[1], u[0]) + rng.uniform(-math.pi / 4, math.pi / 4)
            j = self.hit_impulse_n_s
            out.append((float(t), f, (j * math.cos(a), j * math.sin(a))))
        return out

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def run(
    bench: Bench,
    config: GraspHoldConfig,
    out: Path,
    *,
    progress: ProgressFn = print,
    meta: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Close on the object, hold, record; RunStopped on a fault (the data stay)."""
    hand = bench.hand
    names = list(hand.fingers)
    if (out / "samples.csv").exists():
        raise RunError(f"{out} already holds a grasp hold; give a new --out")
    pose = hand.poses.get(config.pose)
    if pose is None or pose.grasp is None:  # refused before anything is written
        grasps = [p for p in hand.poses if hand.poses[p].grasp is not None]
        raise RunError(f"pose {config.pose!r} is not a grasp pose; grasp poses: {grasps}")
    out.mkdir(parents=True, exist_ok=True)
    goal = pose.theta2(hand.geometry)
    _write_json(out / "meta.json", {"config": config.to_json(), **(meta or {})})
    hand.start_log(out / "telemetry.csv")
    hand.clear_faults()
    hand.pose("open", duration=0.5)
    closing = [i for i in range(len(names)) if goal[i] > 0.2]
    if bench.board is not None:
        for i in closing:
            bench.board.block_finger(i, config.contact_fraction * goal[i], direction="flexion")
    elif bench.operator is not None:
        bench.operator.confirm(f"Place the object for {config.pose!r} in the open hand")
    progress(f"closing on the object: {config.pose} (GRASP, effort {pose.grasp.effort:g})")
    hand.pose(config.pose, duration=1.0, timeout=5.0)
    hand.clock.sleep(0.5)
    opening = {}
    for i in closing:
        g = hand.geometry.fingers[i].geometry
        jac = kinematics.jacobian(g, kinematics.q_from_theta2(g, config.contact_fraction * goal[i]))
        opening[i] = -np.asarray(jac) / np.linalg.norm(jac)  # the tip's way when q shrinks
    hits = config.hit_plan(closing, opening) if bench.board is not None else []
    if bench.board is None and bench.operator is not None:
        bench.operator.say(
            f"holding for {config.duration_s:g} s: hit the fingers with the hammer as you like; "
            "the run records (Ctrl-C stops it, the data stay)"
        )
    seen = len(hand.faults_seen)
    period = 1.0 / config.sample_hz
    t0 = bench.now()
    next_report = 0.0
    k = 0
    with (
        CsvLog(out / "samples.csv", sample_columns(names)) as samples,
        CsvLog(out / "hits.csv", HIT_COLUMNS) as hit_log,
    ):
        while True:
            k += 1
            due = t0 + k * period
            bench.sleep(due - bench.now())
            t = bench.now() - t0
            if t > config.duration_s:
                break
            while hits and hits[0][0] <= t:
                _, f, imp = hits.pop(0)
                bench.hit(f, imp, config.hit_duration_s)
                hit_log.write([f"{bench.now() - t0:.6f}", f, imp[0], imp[1],
                               config.hit_duration_s])  # fmt: skip
            s = bench.tracker.read()
            st = hand.latest
            cur = bench.currents()
            row: list[object] = [
                f"{t:.6f}",
                "baseline" if t < config.baseline_s else "hold",
                *(f"{v:.7f}" for v in s.position_m),
                int(s.visible),
                s.frame,
            ]
            for i in range(len(names)):
                if st is None:
                    row += ["nan"] * len(FINGER_FIELDS)
                    continue
                fs = st.fingers[i]
                row += [f"{fs.theta2:.5f}", f"{fs.target:.5f}", f"{fs.duty_a:.3f}",
                        f"{fs.duty_b:.3f}", fs.mode.name, int(fs.faults),
                        f"{cur[i, 0]:.4f}"]  # fmt: skip
            samples.write(row)
            new = hand.faults_seen[seen:]
            if new:
                raise RunStopped(f"grasp hold at {t:.2f} s: {new[0]}")
            if t >= next_report:
                progress(
                    f"hold {t:7.1f} / {config.duration_s:g} s  "
                    + "  ".join(
                        f"{n} {math.degrees(st.fingers[i].theta2):6.1f} deg"
                        for i, n in enumerate(names)
                    )
                    if st is not None
                    else f"hold {t:.1f} s"
                )
                next_report += max(config.duration_s / 20, 1.0)
    return analyse(out, hand.geometry)


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


def analyse(out: Path, hand_geometry: HandGeometry | None = None) -> dict[str, Any]:
    meta = json.loads((out / "meta.json").read_text())
    config = GraspHoldConfig(**meta["config"])
    geometry = hand_geometry or HandGeometry.default()
    names = [f.name for f in geometry.fingers]
    data = read_log(out / "samples.csv", sample_columns(names))
    rows = data.rows
    if not rows:
        result = {"experiment": "grasp hold (paper Sec. IV-C)", "samples": 0}
        _write_json(out / "results.json", result)
        return result
    t = np.array([float(r["time_s"]) for r in rows])
    base = t < config.baseline_s
    end = t >= t[-1] - config.baseline_s
    hits = read_log(out / "hits.csv", HIT_COLUMNS).rows if (out / "hits.csv").exists() else []
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
    vis = np.array([int(r["visible"]) for r in rows]) == 1
    # A row sampled faster than the tracker measures repeats its last frame: not a new sample.
    tracker_frames = np.array([int(r.get("tracker_frame", -1) or -1) for r in rows])
    repeated = np.zeros(len(rows), dtype=bool)
    repeated[1:] = (tracker_frames[1:] >= 0) & (tracker_frames[1:] == tracker_frames[:-1])
    vis &= ~repeated
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
    _write_json(out / "results.json", result)
    plot(result, rows, names, out / "grasp_hold.png")
    return result


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


def plot(result: dict[str, Any], rows: list[dict[str, Any]], names: list[str], path: Path) -> Path:
    """What the run concludes: each finger's drift (Joint 2 averaged over 1 s outside its
    disturbances, so the drift shows under the readings' noise; the drift from the baseline to
    the end window in the legend), each disturbance's deviation and recovery time, and the
    tracked tip's displacement from its baseline (1 s means of the tracker's new frames)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.array([float(r["time_s"]) for r in rows])
    fig, ax = plt.subplots(3, 1, figsize=(7.5, 7.5), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, n in enumerate(names):
        p = result["fingers"][n]
        c = colours[k % len(colours)]
        th = np.array([float(r[f"{n}_theta2_rad"]) for r in rows])
        held = th.copy()  # the disturbances are the middle panel's: left out of the drift
        for e in p["disturbances"]:
            stop = e["start_s"] + (e["recovery_s"] if e["recovery_s"] is not None else np.inf)
            held[(t >= e["start_s"]) & (t <= stop)] = np.nan
        dev = np.degrees(_running_mean(t, held, 1.0) - p["baseline_theta2_rad"])
        ax[0].plot(t, dev, lw=0.9, color=c,
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
    vis = np.array([int(r["visible"]) for r in rows]) == 1
    frames = np.array([int(r.get("tracker_frame", -1) or -1) for r in rows])
    vis[1:] &= ~((frames[1:] >= 0) & (frames[1:] == frames[:-1]))
    raw = np.array([[float(r[c]) for c in ("raw_x_m", "raw_y_m", "raw_z_m")] for r in rows])
    base = vis & (t < t[0] + 1.0)
    if base.any():
        # The 1 s mean position's distance from the baseline's: the norm of each noisy
        # sample would sit at the noise's size, not at the tip's movement.
        mean_xyz = np.column_stack([_running_mean(t[vis], raw[vis, k], 1.0) for k in range(3)])
        moved = np.linalg.norm(mean_xyz - raw[base].mean(axis=0), axis=1) * 1e3
        ax[2].plot(t[vis], moved, lw=1.0, color="C3", label="1 s mean")
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
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
