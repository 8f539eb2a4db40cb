"""The static loading experiment (paper Sec. IV-A) on the real or the emulated bench.

One finger is held straight and horizontal; payloads hang from its tip (the paper: 0.5 to
3 kg in 0.5 kg steps, three repeats); a tracker's sensor on the tip gives its position.

**How the finger is held, and what the model predicts for it.** The firmware holds the
Joint-2 angle in closed loop (its encoder is on Joint 2). The paper's slide stage held the
tendon displacement q instead. The two are different boundary conditions: with q held,
every tendon's stretch lets the finger sag (24.4 mm at 3 kg); with θ2 held the controller
pulls the actuating tendon until Joint 2 is back, so Tendon 1's stretch drops out, Tendon 2's
stretch turns Joint 1 up (R1 θ1 = R2 θ2 + e2) and Tendon 3's turns Joint 3 down. The run
predicts with the matching boundary condition: per step, the q at which the loaded model
finger has the Joint-2 angle the encoder measured (``utrf.models.calibration.hold_q``, the
same matching as ``planning.plan(match="theta2")``), then the statics there. It reports the
slide-stage (q held) prediction alongside, for comparison with the paper's figures.

Files in the output directory (every CSV append-safe, ``utrf.datalog``):

- ``meta.json``: the run's configuration (what ``--resume`` continues);
- ``registration.json``, ``registration.csv``: the tracker-to-finger registration and the
  samples it was fitted from;
- ``samples.csv``: every tracker sample with the board's telemetry at that moment (step,
  attempt, repeat, load, tracker position raw and in the finger frame, the encoder's θ2 as
  the mean of every telemetry frame since the previous sample and their count and spread,
  duties, motor currents where known);
- ``steps.csv``: one row per *completed* step (the samples' attempt it used): the resume
  marker; ``telemetry.csv``: the Hand's full telemetry stream;
- ``results.json``, ``static_loading.png``: :func:`analyse` (recomputable from the CSVs);
  the calibration's uncertainty carries the Joint-2 reading's (:func:`calibrate`,
  ``utrf.hil.joint2``, ``hil/README.md``).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import CsvLog, read_log
from utrf.hand.state import fault_names
from utrf.hil import joint2
from utrf.hil.bench import BENCH_GAINS, Bench, ProgressFn, finite_mean
from utrf.hil.joint2 import Joint2Frames
from utrf.hil.tracker import (
    NewFrames,
    Registration,
    TrackerError,
    TrackerSample,
    mean_position,
    register,
)
from utrf.models import calibration, kinematics, statics
from utrf.models.geometry import FingerGeometry, HandGeometry
from utrf.models.planning import Target, plan
from utrf.models.statics import Load
from utrf.models.tendons import Limits

PAPER_LOADS_KG = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
SAMPLE_COLUMNS = (
    "step",
    "attempt",
    "repeat",
    "load_kg",
    "time_s",
    "raw_x_m",
    "raw_y_m",
    "raw_z_m",
    "visible",
    "quality",
    "tip_x_m",
    "tip_y_m",
    "out_of_plane_m",
    "theta2_rad",
    "theta2_frames",
    "theta2_frames_sd_rad",
    "target_rad",
    "duty_a",
    "duty_b",
    "faults",
    "current_a_a",
    "current_b_a",
    "tracker_frame",
)
STEP_COLUMNS = (
    "step",
    "attempt",
    "repeat",
    "load_kg",
    "t_start_s",
    "t_end_s",
    "samples",
    "visible",
    "tip_x_m",
    "tip_y_m",
    "tip_sd_m",
    "theta2_rad",
    "theta2_sd_rad",
    "theta2_frames",
    "duty_a",
    "duty_b",
    "current_a_a",
)
REG_COLUMNS = (
    "pose",
    "theta2_rad",
    "model_x_m",
    "model_y_m",
    "raw_x_m",
    "raw_y_m",
    "raw_z_m",
    "samples",
)


class RunError(RuntimeError):
    """A run that cannot start or go on; the message says why and what to do."""


class RunStopped(RuntimeError):
    """The run stopped on a fault or an operator's interrupt; the data taken are kept."""


@dataclass(frozen=True)
class StaticLoadingConfig:
    """A static loading run. SI units (the CLI converts)."""

    finger: int = 1
    loads_kg: tuple[float, ...] = PAPER_LOADS_KG
    repeats: int = 3
    theta2_rad: float = 0.0  # the held pose: straight
    settle_s: float = 1.5
    record_s: float = 1.0
    tracker_hz: float = 40.0
    #: the board's state stream during the run: every frame's Joint-2 reading is averaged
    telemetry_hz: int = 500
    registration_theta2_rad: tuple[float, ...] = (-0.35, 0.0, 0.35, 0.7)
    force: bool = False
    actuator_rating_n: float | None = None  # None: the planner's default (Limits)
    settle_tolerance_rad: float = math.radians(2.0)
    emulated: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.finger <= 4:
            raise RunError(f"finger must be 0..4 (0 thumb .. 4 little), got {self.finger}")
        if not self.loads_kg:
            raise RunError("loads_kg: give at least one payload")
        for w in self.loads_kg:
            if not (math.isfinite(w) and 0 < w <= 10):
                raise RunError(f"loads_kg: each payload must lie in (0, 10] kg, got {w}")
        if len(set(self.loads_kg)) != len(self.loads_kg):
            raise RunError(f"loads_kg: payloads listed twice: {list(self.loads_kg)}")
        if not 1 <= self.repeats <= 100:
            raise RunError(f"repeats must be 1..100, got {self.repeats}")
        for name in ("settle_s", "record_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise RunError(f"{name} must be > 0 s, got {v}")
        if not (math.isfinite(self.tracker_hz) and 1 <= self.tracker_hz <= 1000):
            raise RunError(f"tracker_hz must lie in [1, 1000], got {self.tracker_hz}")
        if not (isinstance(self.telemetry_hz, int) and 1 <= self.telemetry_hz <= 500):
            raise RunError(f"telemetry_hz must be an integer in [1, 500], got {self.telemetry_hz}")
        if self.record_s * self.tracker_hz < 3:
            raise RunError("record_s x tracker_hz must give at least 3 samples a step")
        if len(self.registration_theta2_rad) < 3:
            raise RunError("registration needs at least 3 poses")

    def schedule(self) -> list[tuple[int, int, float]]:
        """(step, repeat, load) in order: each repeat starts unloaded (its reference)."""
        out = []
        step = 0
        for r in range(self.repeats):
            for w in (0.0, *sorted(self.loads_kg)):
                out.append((step, r, w))
                step += 1
        return out

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["loads_kg"] = list(self.loads_kg)
        d["registration_theta2_rad"] = list(self.registration_theta2_rad)
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> StaticLoadingConfig:
        d = dict(d)
        d["loads_kg"] = tuple(d["loads_kg"])
        d["registration_theta2_rad"] = tuple(d["registration_theta2_rad"])
        return cls(**d)


# -- safety -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LoadCheck:
    load_kg: float
    safe: bool
    reasons: tuple[str, ...]
    tension_n: float  # actuating tendon
    motor_force_n: float
    safety_factor: float


def check_loads(
    geometry: FingerGeometry, config: StaticLoadingConfig
) -> tuple[list[LoadCheck], Limits]:
    """The planner's verdict on each payload at the held pose (Joint-2 matching)."""
    limits = (
        Limits()
        if config.actuator_rating_n is None
        else Limits(actuator_rated_force_n=config.actuator_rating_n)
    )
    out = []
    for w in sorted(config.loads_kg):
        p = plan(
            geometry,
            Target.theta2(config.theta2_rad),
            Load(payload_kg=w),
            match="theta2",
            limits=limits,
        )
        out.append(
            LoadCheck(
                w,
                p.safe,
                p.reasons,
                float(p.statics.tensions_n[0]),
                float(p.motor_force_n[0]),
                float(p.statics.safety_factor[0]),
            )
        )
    return out, limits


# -- the run ------------------------------------------------------------------------------------
def _write_json(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=_json_default) + "\n")
    tmp.replace(path)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.floating | np.integer):
        return o.item()
    raise TypeError(f"not JSON: {type(o).__name__}")


def completed_steps(out: Path) -> dict[int, dict[str, Any]]:
    path = out / "steps.csv"
    if not path.exists():
        return {}
    rows = read_log(path, STEP_COLUMNS).rows
    return {int(r["step"]): r for r in rows}


def _attempts(out: Path) -> dict[int, int]:
    path = out / "samples.csv"
    if not path.exists():
        return {}
    seen: dict[int, int] = {}
    for r in read_log(path, SAMPLE_COLUMNS).rows:
        s, a = int(r["step"]), int(r["attempt"])
        seen[s] = max(seen.get(s, 0), a)
    return seen


def check_new_output(out: Path) -> None:
    """RunError if ``out`` already holds a run (a new run must not mix with it)."""
    if (out / "meta.json").exists() or (out / "samples.csv").exists():
        raise RunError(f"{out} already holds a run: continue it with --resume, or give a new --out")


def prepare_output(
    out: Path, config: StaticLoadingConfig, *, resume: bool, extra_meta: dict[str, Any]
) -> StaticLoadingConfig:
    """Create or reopen the output directory; on resume, the stored configuration wins and a
    conflicting one is refused."""
    meta_path = out / "meta.json"
    if resume:
        if not meta_path.exists():
            raise RunError(f"--resume: {out} holds no run (no meta.json); start one without it")
        meta = json.loads(meta_path.read_text())
        stored = StaticLoadingConfig.from_json(meta["config"])
        if stored.emulated != config.emulated:
            raise RunError(
                f"--resume: {out} was run {'emulated' if stored.emulated else 'on the bench'}"
            )
        return stored
    check_new_output(out)
    out.mkdir(parents=True, exist_ok=True)
    _write_json(meta_path, {"config": config.to_json(), **extra_meta})
    return config


def _sample_row(
    bench: Bench,
    reg: Registration,
    frames: Joint2Frames,
    finger: int,
    step: int,
    attempt: int,
    repeat: int,
    load: float,
    new_frames: NewFrames,
) -> dict[str, Any] | None:
    """A row of samples.csv, or None when the tracker returned a frame already taken (read
    faster than it measures: not a new sample)."""
    s = bench.tracker.read()
    if not new_frames.new(s):
        return None
    st = bench.hand.latest
    f = st.fingers[finger] if st is not None else None
    theta2, n_frames, frames_sd = frames.take()
    if n_frames == 0 and f is not None:  # no frame since the last sample: the latest one
        theta2 = f.theta2
    cur = bench.currents()[finger]
    if s.visible:
        xy = reg.to_finger(s.position_m)[0]
        oop = float(reg.out_of_plane(s.position_m)[0])
    else:
        xy, oop = (math.nan, math.nan), math.nan
    return {
        "step": step,
        "attempt": attempt,
        "repeat": repeat,
        "load_kg": load,
        "time_s": f"{s.time_s:.6f}",
        "raw_x_m": f"{s.position_m[0]:.7f}",
        "raw_y_m": f"{s.position_m[1]:.7f}",
        "raw_z_m": f"{s.position_m[2]:.7f}",
        "visible": int(s.visible),
        "quality": f"{s.quality:.3g}",
        "tip_x_m": f"{xy[0]:.7f}",
        "tip_y_m": f"{xy[1]:.7f}",
        "out_of_plane_m": f"{oop:.7f}",
        "theta2_rad": f"{theta2:.6f}",
        "theta2_frames": n_frames,
        "theta2_frames_sd_rad": f"{frames_sd:.6f}",
        "target_rad": f"{f.target:.5f}" if f else "nan",
        "duty_a": f"{f.duty_a:.3f}" if f else "nan",
        "duty_b": f"{f.duty_b:.3f}" if f else "nan",
        "faults": int(f.faults) if f else 0,
        "current_a_a": f"{cur[0]:.4f}",
        "current_b_a": f"{cur[1]:.4f}",
        "tracker_frame": s.frame,
    }


def _check_faults(bench: Bench, finger: int, seen: int, during: str) -> None:
    st = bench.hand.latest
    new = [e for e in bench.hand.faults_seen[seen:] if e.index == finger]
    if new:
        raise RunStopped(f"{during}: {new[0]}")
    if st is not None and st.fingers[finger].faults:
        raise RunStopped(
            f"{during}: finger {finger} has latched {fault_names(int(st.fingers[finger].faults))}"
        )


def _record(
    bench: Bench, config: StaticLoadingConfig, n: int, write: Any, seen: int, during: str
) -> list[dict[str, Any]]:
    rows = []
    period = 1.0 / config.tracker_hz
    for _ in range(4 * n):  # a repeated tracker frame is no sample: read again, up to 4n
        bench.sleep(period)
        row = write()  # logged first: the samples around a fault are kept too
        _check_faults(bench, config.finger, seen, during)
        if row is not None:
            rows.append(row)
            if len(rows) == n:
                break
    return rows


def _registration(
    bench: Bench,
    config: StaticLoadingConfig,
    geometry: FingerGeometry,
    out: Path,
    frames: Joint2Frames,
    progress: ProgressFn,
) -> Registration:
    path = out / "registration.json"
    if path.exists():
        return Registration.from_json(json.loads(path.read_text()))
    f = config.finger
    n = max(3, round(config.record_s * config.tracker_hz))
    seen = len(bench.hand.faults_seen)
    model_pts, raw_pts = [], []
    with CsvLog(out / "registration.csv", REG_COLUMNS) as log:
        for k, th in enumerate(config.registration_theta2_rad):
            bench.hand.move({f: th}, duration=0.4, tolerance=config.settle_tolerance_rad)
            bench.sleep(config.settle_s)
            _check_faults(bench, f, seen, "registration")
            readings: list[TrackerSample] = []
            new_frames = NewFrames()
            frames.take()  # from here on
            for _ in range(4 * n):  # n new tracker frames (a repeated one is no sample)
                bench.sleep(1.0 / config.tracker_hz)
                reading = bench.tracker.read()
                if new_frames.new(reading):
                    readings.append(reading)
                    if len(readings) == n:
                        break
            raw, visible = mean_position(readings)
            if not visible:
                raise RunStopped(f"registration: the tracker never saw the sensor at pose {k}")
            th_m, n_frames, _ = frames.take()  # every frame of the pose's recording
            if n_frames == 0:
                st = bench.hand.latest
                th_m = st.fingers[f].theta2 if st is not None else th
            tip = kinematics.tip_position(geometry, kinematics.q_from_theta2(geometry, th_m))
            log.write([k, f"{th_m:.6f}", tip[0], tip[1], *raw, visible])
            model_pts.append(tip)
            raw_pts.append(raw)
    try:
        reg = register(np.array(model_pts), np.array(raw_pts))
    except TrackerError as exc:
        raise RunStopped(f"registration failed: {exc}") from exc
    _write_json(path, reg.to_json())
    progress(
        f"registration: {reg.points} poses, RMS residual {reg.rms_residual_m * 1e3:.3f} mm "
        "(tracker frame -> finger frame)"
    )
    return reg


def run(
    bench: Bench,
    config: StaticLoadingConfig,
    out: Path,
    *,
    geometry: FingerGeometry,
    progress: ProgressFn = print,
    stop_after_steps: int | None = None,
) -> dict[str, Any]:
    """Run (or continue) the schedule; every sample is logged as it is taken. Returns the
    analysis (:func:`analyse`). Raises RunStopped on a fault: the data stay, and ``--resume``
    continues from the last completed step."""
    f = config.finger
    hand = bench.hand
    done = completed_steps(out)
    attempts = _attempts(out)
    schedule = config.schedule()
    todo = [s for s in schedule if s[0] not in done]
    if not todo:
        progress("every step is already done; analysing")
        return analyse(out, geometry=geometry)
    if done:
        progress(f"resuming: {len(done)} of {len(schedule)} steps done, {len(todo)} to go")
    hand.start_log(out / "telemetry.csv")
    hand.set_telemetry(config.telemetry_hz)
    if bench.emulated:
        hand.set_gains(f, **BENCH_GAINS)
    hand.clear_faults(f)
    hand.move({f: config.theta2_rad}, duration=0.5, tolerance=config.settle_tolerance_rad)
    frames = Joint2Frames(hand, f)
    try:
        reg = _registration(bench, config, geometry, out, frames, progress)
        _run_steps(bench, config, out, todo, attempts, reg, frames, progress, stop_after_steps)
    finally:
        frames.close()
    return analyse(out, geometry=geometry)


def _run_steps(
    bench: Bench,
    config: StaticLoadingConfig,
    out: Path,
    todo: list[tuple[int, int, float]],
    attempts: dict[int, int],
    reg: Registration,
    frames: Joint2Frames,
    progress: ProgressFn,
    stop_after_steps: int | None,
) -> None:
    f = config.finger
    hand = bench.hand
    n_steps = len(config.schedule())
    hand.move({f: config.theta2_rad}, duration=0.4, tolerance=config.settle_tolerance_rad)
    n = max(3, round(config.record_s * config.tracker_hz))
    current_load: float | None = None
    ran = 0
    seen = len(hand.faults_seen)
    with (
        CsvLog(out / "samples.csv", SAMPLE_COLUMNS) as samples,
        CsvLog(out / "steps.csv", STEP_COLUMNS) as steps,
    ):
        try:
            for step, repeat, load in todo:
                if stop_after_steps is not None and ran >= stop_after_steps:
                    break
                attempt = attempts.get(step, 0) + 1
                during = f"step {step} (repeat {repeat + 1}, {load:g} kg)"
                bench.set_payload(f, load, current_load)
                current_load = load
                bench.sleep(config.settle_s)
                _check_faults(bench, f, seen, during)
                hand.wait_settled(
                    config.settle_tolerance_rad, timeout=5.0 * config.settle_s, fingers=[f]
                )
                t0 = bench.now()
                frames.take()  # the step's frames start now

                new_frames = NewFrames()

                def write(step: int = step, attempt: int = attempt, repeat: int = repeat,
                          load: float = load, new_frames: NewFrames = new_frames,
                          ) -> dict[str, Any] | None:  # fmt: skip
                    row = _sample_row(
                        bench, reg, frames, f, step, attempt, repeat, load, new_frames
                    )
                    if row is not None:
                        samples.write(row)
                    return row

                rows = _record(bench, config, n, write, seen, during)
                vis = [r for r in rows if int(r["visible"])]
                if not vis:
                    raise RunStopped(f"{during}: the tracker never saw the sensor")
                xy = np.array([[float(r["tip_x_m"]), float(r["tip_y_m"])] for r in vis])
                tip, tip_sd = xy.mean(axis=0), np.hypot(*xy.std(axis=0))
                th = np.array([float(r["theta2_rad"]) for r in rows])
                n_frames = np.array([int(r["theta2_frames"]) for r in rows])
                theta2 = _frames_mean(th, n_frames)
                mean = {
                    c: finite_mean([float(r[c]) for r in rows])
                    for c in ("duty_a", "duty_b", "current_a_a")
                }
                steps.write(
                    {
                        "step": step,
                        "attempt": attempt,
                        "repeat": repeat,
                        "load_kg": load,
                        "t_start_s": f"{t0:.6f}",
                        "t_end_s": f"{bench.now():.6f}",
                        "samples": len(rows),
                        "visible": len(vis),
                        "tip_x_m": f"{tip[0]:.7f}",
                        "tip_y_m": f"{tip[1]:.7f}",
                        "tip_sd_m": f"{tip_sd:.7f}",
                        "theta2_rad": f"{theta2:.6f}",
                        "theta2_sd_rad": f"{np.nanstd(th):.6f}",
                        "theta2_frames": int(n_frames.sum()),
                        **{c: f"{v:.4f}" for c, v in mean.items()},
                    }
                )
                ran += 1
                progress(
                    f"[{step + 1:2d}/{n_steps}] repeat {repeat + 1}/{config.repeats}  "
                    f"payload {load * 1e3:5.0f} g  tip ({tip[0] * 1e3:8.3f}, "
                    f"{tip[1] * 1e3:7.3f}) mm  sd {tip_sd * 1e3:.3f} mm"
                    f"  theta2 {math.degrees(theta2):+.2f} deg  duty A {mean['duty_a']:.2f}"
                )
        finally:
            if current_load:
                try:
                    bench.set_payload(f, 0.0, current_load)
                except Exception as exc:  # the run is stopping anyway: say so, keep going
                    progress(f"could not remove the payload: {exc}")


def _frames_mean(theta2: np.ndarray, frames: np.ndarray) -> float:
    """A step's Joint-2 angle: the mean over every telemetry frame of its samples (each row
    holds its frames' mean), or over the rows where no frame came (telemetry off)."""
    th = np.asarray(theta2, dtype=float)
    w = np.asarray(frames, dtype=float)
    ok = np.isfinite(th)
    if not (w[ok] > 0).any():
        return finite_mean(th)
    return float((th[ok] * w[ok]).sum() / w[ok].sum())


# -- analysis -------------------------------------------------------------------------------------
@dataclass
class StepData:
    step: int
    repeat: int
    load_kg: float
    tip_m: np.ndarray
    theta2_rad: float
    samples: int
    #: the visible samples, each tracker position with its frames' Joint-2 mean and count
    sample_tips_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    sample_theta2_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sample_frames: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    sample_frames_sd_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))


def load_steps(out: Path) -> list[StepData]:
    """Each completed step, its figures recomputed from the samples of the attempt it used."""
    done = completed_steps(out)
    if not done:
        return []
    rows = read_log(out / "samples.csv", SAMPLE_COLUMNS).rows
    by_key: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for r in rows:
        by_key.setdefault((int(r["step"]), int(r["attempt"])), []).append(r)
    out_steps = []
    for step, srow in sorted(done.items()):
        rs = by_key.get((step, int(srow["attempt"])), [])
        vis = [r for r in rs if int(r["visible"])]
        if not vis:
            continue
        tips = np.array([[float(r["tip_x_m"]), float(r["tip_y_m"])] for r in vis])
        th = np.array([float(r["theta2_rad"]) for r in rs])
        n_frames = np.array([int(r["theta2_frames"]) for r in rs])
        out_steps.append(
            StepData(
                step,
                int(srow["repeat"]),
                float(srow["load_kg"]),
                tips.mean(axis=0),
                _frames_mean(th, n_frames),
                len(rs),
                sample_tips_m=tips,
                sample_theta2_rad=np.array([float(r["theta2_rad"]) for r in vis]),
                sample_frames=np.array([int(r["theta2_frames"]) for r in vis]),
                sample_frames_sd_rad=np.array([float(r["theta2_frames_sd_rad"]) for r in vis]),
            )
        )
    return out_steps


def _model_deflection(
    geometry: FingerGeometry, loads: np.ndarray, theta2: np.ndarray, theta2_ref: np.ndarray
) -> np.ndarray:
    """Model tip displacement (n, 2) from the unloaded finger at ``theta2_ref`` to the loaded
    one at ``theta2`` (Joint-2 hold)."""
    q = calibration.hold_q(geometry, theta2, loads)
    q0 = calibration.hold_q(geometry, theta2_ref, np.zeros_like(loads))
    tip = statics.solve_batch(geometry, q, payload_kg=loads).tip
    tip0 = statics.solve_batch(geometry, q0, payload_kg=0.0).tip
    return tip - tip0


def analyse(out: Path, *, geometry: FingerGeometry, figure: bool = True) -> dict[str, Any]:
    """Results from the logged samples alone: per payload the measured deflection (mean and
    spread over repeats), the model's, their errors (mm and % of the finger's length, as the
    paper), the stiffness, and a calibration of the coupling tendons' effective modulus."""
    meta = json.loads((out / "meta.json").read_text())
    config = StaticLoadingConfig.from_json(meta["config"])
    steps = load_steps(out)
    length = geometry.total_length_m
    g = statics.GRAVITY_MPS2
    refs = {s.repeat: s for s in steps if s.load_kg == 0}
    loaded = [s for s in steps if s.load_kg > 0 and s.repeat in refs]
    result: dict[str, Any] = {
        "experiment": "static loading (paper Sec. IV-A)",
        "finger": config.finger,
        "finger_name": HandGeometry.default().fingers[config.finger].name,
        "finger_length_m": length,
        "hold": {
            "boundary_condition": "Joint-2 angle held by the firmware's closed loop",
            "theta2_setpoint_rad": config.theta2_rad,
            "model": "serial statics with q found per step so that the loaded Joint-2 angle is "
            "the one measured (calibration.hold_q, as planning.plan(match='theta2'))",
        },
        "steps_completed": len(steps),
        "steps_planned": len(config.schedule()),
        "complete": len(steps) == len(config.schedule()),
        "emulated": config.emulated,
    }
    if not loaded:
        result["per_payload"] = []
        _write_json(out / "results.json", result)
        return result
    loads = np.array([s.load_kg for s in loaded])
    meas = np.array([s.tip_m - refs[s.repeat].tip_m for s in loaded])
    th = np.array([s.theta2_rad for s in loaded])
    th_ref = np.array([refs[s.repeat].theta2_rad for s in loaded])
    pred = _model_deflection(geometry, loads, th, th_ref)
    err = np.hypot(*(meas - pred).T)
    nominal_th = np.full(len(loads), config.theta2_rad)
    pred_nominal = _model_deflection(geometry, loads, nominal_th, nominal_th)
    per = []
    for w in sorted(set(loads.tolist())):
        k = loads == w
        mag = np.hypot(*meas[k].T)
        pn = pred_nominal[k][0]
        force = w * g
        slide = statics.solve(geometry, 0.0, Load(payload_kg=w))
        slide0 = statics.solve(geometry, 0.0, Load())
        per.append(
            {
                "load_kg": w,
                "repeats": int(k.sum()),
                "deflection_m": float(mag.mean()),
                "deflection_sd_m": float(mag.std(ddof=1)) if k.sum() > 1 else None,
                "deflection_xy_m": meas[k].mean(axis=0).tolist(),
                "model_deflection_m": float(np.hypot(*pred[k].T).mean()),
                "model_deflection_xy_m": pred[k].mean(axis=0).tolist(),
                "model_at_setpoint_xy_m": pn.tolist(),
                "model_at_setpoint_m": float(np.hypot(*pn)),
                "slide_stage_model_m": float(np.hypot(*(slide.tip_m - slide0.tip_m))),
                "mean_error_m": float(err[k].mean()),
                "max_error_m": float(err[k].max()),
                "stiffness_n_m": float(force / mag.mean()) if mag.mean() > 0 else None,
                "theta2_mean_rad": float(th[k].mean()),
            }
        )
    mags = np.hypot(*meas.T)
    forces = loads * g
    result["per_payload"] = per
    result["error"] = {
        "mean_m": float(err.mean()),
        "max_m": float(err.max()),
        "mean_pct": float(100 * err.mean() / length),
        "max_pct": float(100 * err.max() / length),
        "rows": int(err.size),
        "paper": {"mean_m": 0.545e-3, "max_m": 0.890e-3, "mean_pct": 0.322, "max_pct": 0.520},
    }
    result["stiffness_n_m"] = {
        "least_squares": float((forces * mags).sum() / (mags**2).sum()),
        "at_largest_payload": per[-1]["stiffness_n_m"],
        "paper_slide_stage": 3 * 9.81 / 0.024386,
    }
    try:
        result["calibration"] = calibrate(steps, geometry, source=str(out / "samples.csv"))
    except calibration.CalibrationError as exc:
        result["calibration"] = {"error": str(exc)}
    if "modulus_pa" in result["calibration"]:
        # The calibrated model where the points are: at each step's measured Joint-2 angles
        # (the fit's own basis), not at the setpoint, which it would miss by the hold's error.
        gcal = replace(geometry, tendon_youngs_modulus_pa=result["calibration"]["modulus_pa"])
        pred_cal = _model_deflection(gcal, loads, th, th_ref)
        for p in per:
            k = loads == p["load_kg"]
            p["calibrated_model_deflection_m"] = float(np.hypot(*pred_cal[k].T).mean())
        result["error"]["calibrated_mean_m"] = float(np.hypot(*(meas - pred_cal).T).mean())
    if config.emulated:
        result["emulated_truth"] = meta.get("emulated_truth")
    _write_json(out / "results.json", result)
    if figure:
        plot(result, out / "static_loading.png", geometry)
    return result


def calibrate(
    steps: Sequence[StepData], geometry: FingerGeometry, *, source: str = "<steps>"
) -> dict[str, Any]:
    """The coupling tendons' effective modulus and the tracker's residual offset, fitted to
    the steps' absolute tips held at their measured Joint-2 angles, with what the Joint-2
    reading does to its uncertainty (``utrf.hil.joint2``).

    Each step's tip residual has the covariance of its paired samples (the tracker's noise
    and the readings' random error through the tip's Jacobian), so the fit weighs the steps
    by it and states the modulus's statistical error from it. The readings' leftover bias
    (:func:`joint2.dither_bias_bound` for the noise the run saw, taken as a rectangular
    uncertainty) may follow the load: it is carried as the change of the modulus when the
    loaded steps' angles move by it one way and the unloaded ones' the other. The modulus's
    standard uncertainty is the two combined."""
    loads = np.array([s.load_kg for s in steps])
    theta2 = np.array([s.theta2_rad for s in steps])
    jac = joint2.tip_jacobian(geometry, theta2, loads)
    cov, pooled = joint2.step_covariances(
        [s.sample_tips_m for s in steps], [s.sample_theta2_rad for s in steps], jac
    )
    data = calibration.CalibrationData(
        loads,
        np.zeros(len(steps)),
        tip_m=np.array([s.tip_m for s in steps]),
        source=source,
        theta2_rad=theta2,
        tip_cov_m2=cov,
    )
    names = ["modulus", "tip_offset"]
    fit = calibration.fit(data, geometry, fit_params=names)
    modulus = fit.params.geometry.tendon_youngs_modulus_pa
    sd_stat = fit.std_errors["modulus"]
    # The same fit if the encoder were perfect: the tracker's noise alone, taken as the paired
    # samples' spread across the tip's Jacobian (the tracker's noise is isotropic in the plane).
    across = np.array([[-j[1], j[0]] / np.hypot(*j) for j in jac])
    tracker_var = np.mean([a @ pooled @ a for a in across])
    n = np.array([max(len(s.sample_theta2_rad), 1) for s in steps])
    tracker_only = calibration.fit(
        replace(data, tip_cov_m2=tracker_var * np.eye(2)[None] / n[:, None, None]),
        geometry,
        fit_params=names,
    ).std_errors["modulus"]
    frames = np.concatenate([s.sample_frames for s in steps])
    frames_sd = np.concatenate([s.sample_frames_sd_rad for s in steps])
    noise = joint2.encoder_noise_counts(frames, frames_sd)
    bound_rad = joint2.dither_bias_bound(noise) * joint2.COUNT_RAD  # NaN noise: half a count
    shift = np.where(loads > 0, 1.0, -1.0) * bound_rad / math.sqrt(3)
    moved = [
        calibration.fit(replace(data, theta2_rad=theta2 + sign * shift), geometry,
                        fit_params=names).params.geometry.tendon_youngs_modulus_pa
        for sign in (1.0, -1.0)
    ]  # fmt: skip
    sd_resolution = max(abs(m - modulus) for m in moved)
    out = fit.to_json()
    warnings = list(out["warnings"])
    if not noise >= joint2.DITHER_MIN_COUNTS:
        warnings.append(
            f"the Joint-2 readings are hardly dithered (encoder noise {noise:.2f} counts RMS): "
            "a held finger can settle at a count's edge under load, so the modulus carries "
            f"+-{sd_resolution / 1e9:.1f} GPa for the encoder's resolution"
        )
    total_frames = int(frames[frames > 0].sum())
    many = (frames > 1) & np.isfinite(frames_sd)
    frame_sd = (
        math.sqrt((frames * frames_sd**2)[many].sum() / (frames[many] - 1).sum())
        if many.any()
        else math.nan
    )  # one reading's error, dithered: noise and quantisation
    out.update(
        {
            "modulus_pa": modulus,
            "modulus_sd_pa": None if sd_stat is None else math.hypot(sd_stat, sd_resolution),
            "modulus_sd_statistical_pa": sd_stat,
            "modulus_sd_joint2_resolution_pa": sd_resolution,
            "modulus_sd_tracker_only_pa": tracker_only,
            "joint2": {
                "count_rad": joint2.COUNT_RAD,
                "frames_per_step": float(total_frames / len(steps)),
                "encoder_noise_counts": noise,
                "dither_bias_bound_rad": bound_rad,
                "frame_sd_rad": frame_sd,
                # a step's mean reading, dithered: one reading's error over sqrt(its frames)
                "step_se_rad": frame_sd / math.sqrt(max(total_frames / len(steps), 1.0)),
                "paired_sample_sd_m": np.sqrt(np.diag(pooled)).tolist(),
            },
            "warnings": warnings,
        }
    )
    return out


def plot(result: dict[str, Any], path: Path, geometry: FingerGeometry) -> Path:
    """Measured against the model (as the paper's Fig. 8), with the calibrated model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    per = result["per_payload"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    w = np.array([p["load_kg"] for p in per])
    d = np.array([p["deflection_m"] for p in per]) * 1e3
    sd = np.array([p["deflection_sd_m"] or 0.0 for p in per]) * 1e3
    ax.errorbar(w, d, yerr=sd, fmt="o", capsize=3, label="measured (mean ± sd over repeats)")
    ax.plot(w, [p["model_deflection_m"] * 1e3 for p in per], "s--", mfc="none",
            label="model at the measured Joint-2 angles")  # fmt: skip
    grid = np.linspace(0, max(w.max(), 0.5), 25)
    th = np.full(grid.size, result["hold"]["theta2_setpoint_rad"])
    nominal = np.hypot(*_model_deflection(geometry, grid, th, th).T) * 1e3
    ax.plot(grid, nominal, "-", label="model, Joint 2 held at the setpoint")
    cal = result.get("calibration", {})
    if "modulus_pa" in cal and all("calibrated_model_deflection_m" in p for p in per):
        fitted = np.array([p["calibrated_model_deflection_m"] for p in per]) * 1e3
        ax.plot(w, fitted, "d:", mfc="none",
                label=f"calibrated model (E = {cal['modulus_pa'] / 1e9:.0f} GPa) at the "
                "measured Joint-2 angles")  # fmt: skip
    ax.set_xlabel("payload at the tip (kg)")
    ax.set_ylabel("tip displacement (mm)")
    e = result.get("error", {})
    name = result.get("finger_name") or f"finger {result['finger']}"
    ax.set_title(
        f"Static loading, {name}: mean error "
        f"{e.get('mean_m', math.nan) * 1e3:.3f} mm, "
        f"max {e.get('max_m', math.nan) * 1e3:.3f} mm",
        fontsize=9,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def describe(result: dict[str, Any]) -> str:
    """The results as a table for people (mm, says so)."""
    lines = [
        "payload  measured (mm)       model (mm)  error mean/max (mm)  stiffness (N/m)  "
        "slide-stage model (mm)"
    ]
    for p in result.get("per_payload", []):
        sd = p["deflection_sd_m"]
        lines.append(
            f"{p['load_kg']:5.2f} kg  {p['deflection_m'] * 1e3:7.3f} ± "
            f"{(sd or 0) * 1e3:5.3f}  {p['model_deflection_m'] * 1e3:9.3f}    "
            f"{p['mean_error_m'] * 1e3:6.3f} / {p['max_error_m'] * 1e3:6.3f}      "
            f"{(p['stiffness_n_m'] or math.nan):9.0f}         {p['slide_stage_model_m'] * 1e3:7.3f}"
        )
    e = result.get("error")
    if e:
        lines.append(
            f"error over {e['rows']} loaded steps: mean {e['mean_m'] * 1e3:.3f} mm "
            f"({e['mean_pct']:.3f} % of the finger), max {e['max_m'] * 1e3:.3f} mm "
            f"({e['max_pct']:.3f} %); the paper: 0.545 mm (0.322 %), 0.890 mm (0.520 %)"
        )
    cal = result.get("calibration", {})
    if "modulus_pa" in cal:
        sd = cal["modulus_sd_pa"]
        j2 = cal.get("joint2", {})
        lines.append(
            f"calibration: effective tendon modulus {cal['modulus_pa'] / 1e9:.1f} "
            f"± {(sd or math.nan) / 1e9:.1f} GPa; after the fit mean error "
            f"{cal['mean_error_m'] * 1e3:.3f} mm, max {cal['max_error_m'] * 1e3:.3f} mm"
        )
        if j2:
            lines.append(
                f"  its uncertainty: statistical "
                f"{(cal['modulus_sd_statistical_pa'] or math.nan) / 1e9:.1f} GPa (the tracker "
                f"and a step's Joint-2 reading, +-{j2['step_se_rad'] * 1e3:.2f} mrad from "
                f"{j2['frames_per_step']:.0f} frames; with a perfect encoder "
                f"{(cal['modulus_sd_tracker_only_pa'] or math.nan) / 1e9:.1f}), the encoder's "
                f"resolution {cal['modulus_sd_joint2_resolution_pa'] / 1e9:.1f} GPa (its noise "
                f"{j2['encoder_noise_counts']:.2f} ADC counts RMS)"
            )
        for w in cal.get("warnings", []):
            lines.append(f"  WARNING: {w}")
    truth = result.get("emulated_truth")
    if truth:
        lines.append(
            f"emulated truth (hidden from the analysis): coupling modulus "
            f"{truth['coupling_modulus_pa'] / 1e9:.1f} GPa"
        )
    if not result.get("complete", True):
        lines.append(
            f"INCOMPLETE: {result['steps_completed']} of {result['steps_planned']} steps "
            "(continue with --resume)"
        )
    return "\n".join(lines)


def default_time() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


__all__: Sequence[str] = (
    "PAPER_LOADS_KG",
    "RunError",
    "RunStopped",
    "StaticLoadingConfig",
    "analyse",
    "check_loads",
    "describe",
    "run",
)
