"""A static loading run's results from its files alone (``samples.csv``, ``steps.csv``,
``meta.json``): per payload the measured deflection against the model's, the errors, the
stiffness, and the calibration of the coupling tendons' modulus. What the run and
``utrf hil analyse`` share (``utrf.hil.static_loading``)."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import read_rows
from utrf.hil import joint2
from utrf.hil.runs import write_json
from utrf.hil.static_loading.config import (
    SAMPLE_COLUMNS,
    StaticLoadingConfig,
    completed_steps,
    frames_mean,
)
from utrf.models import calibration, statics
from utrf.models.geometry import FingerGeometry, HandGeometry
from utrf.models.statics import Load


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
    rows = read_rows(out / "samples.csv", SAMPLE_COLUMNS)
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
                frames_mean(th, n_frames),
                len(rs),
                sample_tips_m=tips,
                sample_theta2_rad=np.array([float(r["theta2_rad"]) for r in vis]),
                sample_frames=np.array([int(r["theta2_frames"]) for r in vis]),
                sample_frames_sd_rad=np.array([float(r["theta2_frames_sd_rad"]) for r in vis]),
            )
        )
    return out_steps


def model_deflection(
    geometry: FingerGeometry, loads: np.ndarray, theta2: np.ndarray, theta2_ref: np.ndarray
) -> np.ndarray:
    """Model tip displacement (n, 2) from the unloaded finger at ``theta2_ref`` to the loaded
    one at ``theta2`` (Joint-2 hold)."""
    q = calibration.hold_q(geometry, theta2, loads)
    q0 = calibration.hold_q(geometry, theta2_ref, np.zeros_like(loads))
    tip = statics.solve_batch(geometry, q, payload_kg=loads).tip
    tip0 = statics.solve_batch(geometry, q0, payload_kg=0.0).tip
    return tip - tip0


def analyse(out: Path, *, geometry: FingerGeometry) -> dict[str, Any]:
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
        write_json(out / "results.json", result)
        return result
    loads = np.array([s.load_kg for s in loaded])
    meas = np.array([s.tip_m - refs[s.repeat].tip_m for s in loaded])
    th = np.array([s.theta2_rad for s in loaded])
    th_ref = np.array([refs[s.repeat].theta2_rad for s in loaded])
    pred = model_deflection(geometry, loads, th, th_ref)
    err = np.hypot(*(meas - pred).T)
    nominal_th = np.full(len(loads), config.theta2_rad)
    pred_nominal = model_deflection(geometry, loads, nominal_th, nominal_th)
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
        pred_cal = model_deflection(gcal, loads, th, th_ref)
        for p in per:
            k = loads == p["load_kg"]
            p["calibrated_model_deflection_m"] = float(np.hypot(*pred_cal[k].T).mean())
        result["error"]["calibrated_mean_m"] = float(np.hypot(*(meas - pred_cal).T).mean())
    if config.emulated:
        result["emulated_truth"] = meta.get("emulated_truth")
    write_json(out / "results.json", result)
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
    sd = fit.std_errors["modulus"]
    sd_stat = sd if isinstance(sd, float) else None  # one parameter: a number, or None (no fit)
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
