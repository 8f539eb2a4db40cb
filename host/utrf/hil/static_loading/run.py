"""Taking a static loading run's data: the registration, then the schedule's steps, each
sample written as it is taken (``utrf.hil.static_loading``). A fault stops the run with every
sample kept; ``--resume`` continues from the last completed step. The results are
:mod:`utrf.hil.static_loading.analysis`'s, from the files alone."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import CsvLog, read_rows
from utrf.hand.state import fault_names
from utrf.hil.joint2 import Joint2Frames
from utrf.hil.rig import RIG_GAINS, Rig
from utrf.hil.runs import ProgressFn, RunError, RunStopped, finite_mean, write_json
from utrf.hil.static_loading.config import (
    REG_COLUMNS,
    SAMPLE_COLUMNS,
    STEP_COLUMNS,
    StaticLoadingConfig,
    completed_steps,
    frames_mean,
)
from utrf.hil.tracker import (
    NewFrames,
    Registration,
    TrackerError,
    TrackerSample,
    mean_position,
    register,
)
from utrf.models import kinematics
from utrf.models.geometry import FingerGeometry
from utrf.models.planning import Target, plan
from utrf.models.statics import Load
from utrf.models.tendons import Limits


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


def _attempts(out: Path) -> dict[int, int]:
    path = out / "samples.csv"
    if not path.exists():
        return {}
    seen: dict[int, int] = {}
    for r in read_rows(path, SAMPLE_COLUMNS):
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
                f"--resume: {out} was run {'emulated' if stored.emulated else 'on the rig'}"
            )
        return stored
    check_new_output(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(meta_path, {"config": config.to_json(), **extra_meta})
    return config


def _sample_row(
    rig: Rig,
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
    s = rig.tracker.read()
    if not new_frames.new(s):
        return None
    st = rig.hand.latest
    f = st.fingers[finger] if st is not None else None
    theta2, n_frames, frames_sd = frames.take()
    if n_frames == 0 and f is not None:  # no frame since the last sample: the latest one
        theta2 = f.theta2
    cur = rig.currents()[finger]
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


def _check_faults(rig: Rig, finger: int, seen: int, during: str) -> None:
    st = rig.hand.latest
    new = [e for e in rig.hand.faults_seen[seen:] if e.index == finger]
    if new:
        raise RunStopped(f"{during}: {new[0]}")
    if st is not None and st.fingers[finger].faults:
        raise RunStopped(
            f"{during}: finger {finger} has latched {fault_names(int(st.fingers[finger].faults))}"
        )


def _record(
    rig: Rig, config: StaticLoadingConfig, n: int, write: Any, seen: int, during: str
) -> list[dict[str, Any]]:
    rows = []
    period = 1.0 / config.tracker_hz
    for _ in range(4 * n):  # a repeated tracker frame is no sample: read again, up to 4n
        rig.sleep(period)
        row = write()  # logged first: the samples around a fault are kept too
        _check_faults(rig, config.finger, seen, during)
        if row is not None:
            rows.append(row)
            if len(rows) == n:
                break
    return rows


def _registration(
    rig: Rig,
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
    seen = len(rig.hand.faults_seen)
    model_pts, raw_pts = [], []
    with CsvLog(out / "registration.csv", REG_COLUMNS) as log:
        for k, th in enumerate(config.registration_theta2_rad):
            rig.hand.move({f: th}, duration=0.4, tolerance=config.settle_tolerance_rad)
            rig.sleep(config.settle_s)
            _check_faults(rig, f, seen, "registration")
            readings: list[TrackerSample] = []
            new_frames = NewFrames()
            frames.take()  # from here on
            for _ in range(4 * n):  # n new tracker frames (a repeated one is no sample)
                rig.sleep(1.0 / config.tracker_hz)
                reading = rig.tracker.read()
                if new_frames.new(reading):
                    readings.append(reading)
                    if len(readings) == n:
                        break
            raw, visible = mean_position(readings)
            if not visible:
                raise RunStopped(f"registration: the tracker never saw the sensor at pose {k}")
            th_m, n_frames, _ = frames.take()  # every frame of the pose's recording
            if n_frames == 0:
                st = rig.hand.latest
                th_m = st.fingers[f].theta2 if st is not None else th
            tip = kinematics.tip_position(geometry, kinematics.q_from_theta2(geometry, th_m))
            log.write([k, f"{th_m:.6f}", tip[0], tip[1], *raw, visible])
            model_pts.append(tip)
            raw_pts.append(raw)
    try:
        reg = register(np.array(model_pts), np.array(raw_pts))
    except TrackerError as exc:
        raise RunStopped(f"registration failed: {exc}") from exc
    write_json(path, reg.to_json())
    progress(
        f"registration: {reg.points} poses, RMS residual {reg.rms_residual_m * 1e3:.3f} mm "
        "(tracker frame -> finger frame)"
    )
    return reg


def run(
    rig: Rig,
    config: StaticLoadingConfig,
    out: Path,
    *,
    geometry: FingerGeometry,
    progress: ProgressFn = print,
    stop_after_steps: int | None = None,
) -> None:
    """Run (or continue) the schedule; every sample is logged as it is taken (the results:
    ``report.write``, from the files). Raises RunStopped on a fault: the data stay, and
    ``--resume`` continues from the last completed step."""
    f = config.finger
    hand = rig.hand
    done = completed_steps(out)
    attempts = _attempts(out)
    schedule = config.schedule()
    todo = [s for s in schedule if s[0] not in done]
    if not todo:
        progress("every step is already done")
        return
    if done:
        progress(f"resuming: {len(done)} of {len(schedule)} steps done, {len(todo)} to go")
    hand.start_log(out / "telemetry.csv")
    hand.set_telemetry(config.telemetry_hz)
    if rig.emulated:
        hand.set_gains(f, **RIG_GAINS)
    hand.clear_faults(f)
    hand.move({f: config.theta2_rad}, duration=0.5, tolerance=config.settle_tolerance_rad)
    frames = Joint2Frames(hand, f)
    try:
        reg = _registration(rig, config, geometry, out, frames, progress)
        _run_steps(rig, config, out, todo, attempts, reg, frames, progress, stop_after_steps)
    finally:
        frames.close()


def _run_steps(
    rig: Rig,
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
    hand = rig.hand
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
                rig.set_payload(f, load, current_load)
                current_load = load
                rig.sleep(config.settle_s)
                _check_faults(rig, f, seen, during)
                hand.wait_settled(
                    config.settle_tolerance_rad, timeout=5.0 * config.settle_s, fingers=[f]
                )
                t0 = rig.now()
                frames.take()  # the step's frames start now

                new_frames = NewFrames()

                def write(step: int = step, attempt: int = attempt, repeat: int = repeat,
                          load: float = load, new_frames: NewFrames = new_frames,
                          ) -> dict[str, Any] | None:  # fmt: skip
                    row = _sample_row(rig, reg, frames, f, step, attempt, repeat, load, new_frames)
                    if row is not None:
                        samples.write(row)
                    return row

                rows = _record(rig, config, n, write, seen, during)
                vis = [r for r in rows if int(r["visible"])]
                if not vis:
                    raise RunStopped(f"{during}: the tracker never saw the sensor")
                xy = np.array([[float(r["tip_x_m"]), float(r["tip_y_m"])] for r in vis])
                tip, tip_sd = xy.mean(axis=0), np.hypot(*xy.std(axis=0))
                th = np.array([float(r["theta2_rad"]) for r in rows])
                n_frames = np.array([int(r["theta2_frames"]) for r in rows])
                theta2 = frames_mean(th, n_frames)
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
                        "t_end_s": f"{rig.now():.6f}",
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
                    rig.set_payload(f, 0.0, current_load)
                except Exception as exc:  # the run is stopping anyway: say so, keep going
                    progress(f"could not remove the payload: {exc}")
