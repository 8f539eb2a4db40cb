"""A static loading run's results for people: the figure (as the paper's Fig. 8) and the
table (mm, says so). :func:`write` analyses a run's files and writes both its results and
its figure: what the run's command and ``utrf hil analyse`` print."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from utrf.hil.static_loading.analysis import analyse, model_deflection
from utrf.models.geometry import FingerGeometry

FIGURE = "static_loading.png"


def write(out: Path, geometry: FingerGeometry) -> dict[str, Any]:
    """The run's results (``results.json``) and its figure, from its files alone."""
    result = analyse(out, geometry=geometry)
    if result["per_payload"]:  # a run killed before its first loaded step has no figure
        plot(result, out / FIGURE, geometry)
    return result


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
    nominal = np.hypot(*model_deflection(geometry, grid, th, th).T) * 1e3
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
