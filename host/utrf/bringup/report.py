"""The bring-up's report folder: ``report.md`` (what was found, what was set, the checks),
``measurements.json`` (every measurement), ``telemetry.json`` (the 1 kHz stream the bring-up
read, per finger channel) and a picture per finger (its closed-loop check before and after
tuning on one plot)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from utrf.hand.state import HandState

if TYPE_CHECKING:
    from utrf.bringup.procedure import BringupResult, FingerResult


def _plot(r: FingerResult, path: Path) -> Path | None:
    if not r.checks:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    for c in r.checks:
        if not c.t:
            continue
        t0 = c.t[0]
        ax.plot([t - t0 for t in c.t], [math.degrees(v) for v in c.theta2], label=c.label)
    c = r.checks[-1]
    if c.t:
        ax.plot(
            [t - c.t[0] for t in c.t],
            [math.degrees(v) for v in c.target],
            "k--",
            lw=0.8,
            label="setpoint",
        )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("Joint-2 angle (deg)")
    ax.set_title(f"{r.name}: closed-loop check before and after tuning")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_report(result: BringupResult, out: Path, samples: list[HandState]) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    (out / "measurements.json").write_text(json.dumps(result.to_dict(), indent=1))
    (out / "telemetry.json").write_text(
        json.dumps(
            {
                "board_time_s": [s.board_time for s in samples],
                "theta2_rad": [list(s.theta2) for s in samples],
                "duty_a": [[f.duty_a for f in s.fingers] for s in samples],
                "duty_b": [[f.duty_b for f in s.fingers] for s in samples],
            }
        )
    )
    lines = [
        "# Bring-up report",
        "",
        f"**{result.message}** (board time {result.board_time_s:.1f} s; duty never above "
        f"{result.bounds.duty:g})",
        "",
    ]
    for r in result.fingers:
        lines += [f"## {r.name}", ""]
        if not r.findings:
            lines.append("Built as the model says.")
        for fd in r.findings:
            state = "fixed by configuration" if fd.fixable else "**not fixable by configuration**"
            lines.append(f"- **{fd.kind}**: {fd.message}. Fix: {fd.fix} ({state}).")
        lines.append("")
        if r.stops:
            lines.append(
                f"Stops: open {math.degrees(r.stops['open_rad']):.1f}°, closed "
                f"{math.degrees(r.stops['closed_rad']):.1f}°; encoder offset "
                f"{r.stops['offset_rad']:.4f} rad."
            )
        if r.plant:
            p = r.plant
            lines.append(
                f"Plant: K {p['K']:.2f} rad/s per duty, τ {p['tau'] * 1e3:.1f} ms, friction "
                f"{p['u_f']:.3f} duty, backlash {math.degrees(p['backlash_rad']):.1f}°."
            )
        if r.tuning:
            tn = r.tuning
            lines.append(
                f"Tuning ({tn['method']}): crossover {tn['crossover_rad_s']:.1f} rad/s, phase "
                f"margin {tn['phase_margin_deg']:.0f}°; gains {tn['gains']}, motion {tn['motion']}."
            )
        if r.checks:
            lines += [
                "",
                "| check | RMS (°) | worst (°) | overshoot (°) | settling (s) |",
                "|---|---|---|---|---|",
            ]
            for c in r.checks:
                lines.append(
                    f"| {c.label} | {math.degrees(c.rms_rad):.2f} "
                    f"| {math.degrees(c.worst_rad):.2f} "
                    f"| {math.degrees(c.overshoot_rad):.2f} | {c.settle_s:.2f} |"
                )
        pic = _plot(r, out / f"{r.name}.png")
        if pic is not None:
            lines += ["", f"![{r.name}]({pic.name})"]
        lines.append("")
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
