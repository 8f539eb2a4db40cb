"""Make the models page's figures and print the numbers quoted beside them.

    python -m tools.model_figures docs/figures      # make figures-models

Writes ``workspace.png`` (Fig. 3), ``stiffness.png`` (Fig. 8, with the paper's 3 kg point and
the serial model calibrated to it) and ``model_gap.png`` (serial against printed over the
flexion range), all for the default finger, and prints a summary of what they show.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from utrf.models import (
    calibration,
    energy,
    kinematics,
    planning,
    statics,
    stiffness,
    tendons,
    workspace,
)
from utrf.models.geometry import FingerGeometry

GAP_PAYLOAD_KG = 0.2


def model_gap(geom: FingerGeometry, payload_kg: float = GAP_PAYLOAD_KG, n: int = 61) -> dict:
    """Tip deflection of both models where the finger can go: θ1 within its range and the
    coupling holding."""
    (clo, chi), (rlo, rhi) = tendons.coupling_q_range_m(geom), geom.q_range_m
    lo, hi = max(clo, rlo), min(chi, rhi)
    q = np.linspace(lo, hi, n)
    out: dict = {"q_m": q, "flexion": kinematics.flexion_from_q(geom, q)}
    for m in statics.MODELS:
        b = statics.solve_batch(geom, q, payload_kg=payload_kg, model=m)
        zero = statics.solve_batch(geom, q, model=m)
        out[m] = np.hypot(*(b.tip - zero.tip).T)
    return out


def energy_agreement(geom: FingerGeometry, n: int = 300, seed: int = 5) -> tuple[float, float]:
    """Largest tip (m) and tension (N) difference, Algorithm 1 (serial) against the energy
    minimum, over n random cases: q over the range, 0-3 kg, ±10 N, ±0.2 N m, gravity on."""
    rng = np.random.default_rng(seed)
    tip_diff = tension_diff = 0.0
    for _ in range(n):
        load = statics.Load(
            payload_kg=float(rng.uniform(0, 3)),
            tip_force_n=(float(rng.uniform(-10, 10)), float(rng.uniform(-10, 10))),
            tip_moment_nm=float(rng.uniform(-0.2, 0.2)),
        )
        q = float(rng.uniform(*geom.q_range_m))
        a = statics.solve(geom, q, load, threshold_m=1e-12)
        b = energy.solve_energy(geom, q, load)
        tip_diff = max(tip_diff, float(np.hypot(*(a.tip_m - b.tip))))
        tension_diff = max(tension_diff, float(np.abs(a.net_tensions_n - b.net_tensions_n).max()))
    return tip_diff, tension_diff


def largest_safe_payload(geom: FingerGeometry, flexion: float) -> float:
    """Largest payload (kg) that ``planning.plan`` accepts at a flexion (bisection, 1 g)."""

    def safe(kg: float) -> bool:
        return planning.plan(
            geom, planning.Target.flexion(flexion), statics.Load(payload_kg=kg)
        ).safe

    lo, hi = 0.0, 5.0
    if not safe(lo):
        return 0.0
    while hi - lo > 1e-3:
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if safe(mid) else (lo, mid)
    return lo


def _plot_gap(gap: dict, out: Path, payload_kg: float) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 3.4), dpi=110)
    for m, style in zip(statics.MODELS, ("-", "--"), strict=True):
        ax.plot(gap["flexion"], gap[m] * 1e3, style, label=f"{m} model")
    ax.set_xlabel("normalised flexion (q / q_max)")
    ax.set_ylabel(f"tip deflection under {payload_kg:g} kg (mm)")
    ax.set_title("Serial against printed (Eq. 16) over the coupling's range", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def make(outdir: str | Path, geom: FingerGeometry | None = None) -> list[str]:
    """Write the figures into ``outdir``; return the summary lines."""
    geom = geom if geom is not None else FingerGeometry.default()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    lines: list[str] = []

    ws = workspace.swept(geom)
    areas = workspace.areas(geom, fine=ws)
    workspace.plot(ws, geom, outdir / "workspace.png", extrapolated=areas)
    a = areas.link_areas_m2 * 1e6
    lines.append(
        f"workspace: Link 1 {a[0]:.0f} mm², Link 2 {a[1]:.0f} mm², Link 3 {a[2]:.0f} mm², "
        f"Links 1 and 2 overlap {areas.overlap_12_m2 * 1e6:.0f} mm² "
        f"(raster {ws.resolution_m * 1e3:g} mm, extrapolated)"
    )

    curves = [stiffness.deflection_curve(geom, model=m) for m in statics.MODELS]
    paper = calibration.CalibrationData(
        load_kg=np.array([stiffness.PAPER_LOAD_KG]),
        q_m=np.zeros(1),
        deflection_m=np.array([stiffness.PAPER_DEFLECTION_M]),
        source="paper",
    )
    fit = calibration.fit(paper, geom)
    calibrated = stiffness.deflection_curve(fit.params.geometry, model="serial")
    e_eff = fit.params.geometry.tendon_youngs_modulus_pa
    stiffness.plot(
        [*curves, calibrated],
        outdir / "stiffness.png",
        labels=[
            "serial model",
            "printed model",
            f"serial, E fitted to the paper ({e_eff / 1e9:.0f} GPa)",
        ],
    )
    for c in curves:
        lines.append(
            f"stiffness ({c.model}): {c.at(3.0) * 1e3:.3f} mm at 3 kg, "
            f"{c.secant_stiffness_n_per_m:.4g} N/m (slope {c.fit_stiffness_n_per_m:.4g} N/m), "
            f"T1 {c.tensions_n[-1, 0]:.0f} N"
        )
    lines.append(
        f"paper: {stiffness.PAPER_DEFLECTION_M * 1e3:.3f} mm at 3 kg, "
        f"{stiffness.PAPER_STIFFNESS_N_PER_M:.4g} N/m; serial model matches with an effective "
        f"modulus of {e_eff / 1e9:.1f} GPa"
    )

    gap = model_gap(geom)
    _plot_gap(gap, outdir / "model_gap.png", GAP_PAYLOAD_KG)
    ratio = gap["serial"] / np.maximum(gap["printed"], 1e-15)
    lines.append(
        f"model gap under {GAP_PAYLOAD_KG:g} kg over flexion "
        f"[{gap['flexion'][0]:.2f}, {gap['flexion'][-1]:.2f}]: serial/printed deflection "
        f"ratio {ratio.min():.2f}..{ratio.max():.2f}, largest difference "
        f"{np.abs(gap['serial'] - gap['printed']).max() * 1e3:.2f} mm"
    )
    tip_diff, tension_diff = energy_agreement(geom)
    lines.append(
        f"energy check over 300 random cases (threshold 1e-12 m): tip within {tip_diff:.2g} m, "
        f"tensions within {tension_diff:.2g} N"
    )
    lines.append(
        "largest payload a plan accepts (default limits): "
        + ", ".join(
            f"flexion {f:g}: {largest_safe_payload(geom, f):.3f} kg" for f in (0.0, 0.3, 0.6)
        )
    )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tools.model_figures", description=(__doc__ or "").split("\n")[0]
    )
    parser.add_argument("outdir", type=Path, help="directory for the PNG files")
    args = parser.parse_args(argv)
    for line in make(args.outdir):
        print(line)
    print(f"wrote {args.outdir}/workspace.png, stiffness.png, model_gap.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
