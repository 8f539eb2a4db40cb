"""Benchmark of the statics solver (Algorithm 1): speed and iterations against threshold.

    python -m tools.bench_models --update docs/benchmarks.md --json build/bench/models.json

Measures, on the default finger: one scalar ``statics.solve`` (3 kg at the straight pose;
target at most 20 µs, issue 11 goal 6), one vectorised ``statics.solve_batch`` of 10,000
random load cases (target at least 2e5 solves/s), solves per second, and the iterations
Algorithm 1 needs against its threshold; and the MuJoCo hand (``utrf.models.mjcf``): one
``mj_step`` of the whole hand, one MuJoCo equilibrium of a finger, one off-screen picture.
Timings are the median of repeated runs (time.perf_counter). ``--update`` replaces the
"## Models" section of the Markdown file and leaves the other sections alone.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import scipy

from tools.doc_sections import cpu_name, write_section
from utrf.models import statics, tendons
from utrf.models.geometry import FingerGeometry, HandGeometry
from utrf.models.statics import Load

COMMAND = "make bench-models  # python -m tools.bench_models --update docs/benchmarks.md"
THRESHOLDS_M = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)


def _median_time(fn: Callable[[], object], repeats: int) -> float:
    fn()  # warm up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _cpu_time(fn: Callable[[], object], repeats: int) -> float:
    """Process CPU time per call over ``repeats`` calls: time spent waiting for a core while
    other jobs run is not in it (time lost to a busy sibling hyperthread still is)."""
    fn()
    t0 = time.process_time()
    for _ in range(repeats):
        fn()
    return (time.process_time() - t0) / repeats


def random_cases(geom: FingerGeometry, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """q over the tendon's range, 0-3 kg payload, a ±10 N force, a ±0.2 N m moment."""
    rng = np.random.default_rng(seed)
    return {
        "q": rng.uniform(*geom.q_range_m, n),
        "payload_kg": rng.uniform(0.0, 3.0, n),
        "tip_force_n": rng.uniform(-10.0, 10.0, (n, 2)),
        "tip_moment_nm": rng.uniform(-0.2, 0.2, n),
    }


def random_fingers(n: int, seed: int = 1) -> list[FingerGeometry]:
    """Valid fingers over the tests' ranges: lengths 20-90 mm, radii 2-15 mm, E 50-250 GPa,
    tendons 0.5-1.5 mm, actuating tendon 30-300 mm, links up to 50 g."""
    rng = np.random.default_rng(seed)
    out: list[FingerGeometry] = []
    while len(out) < n:
        L, R = rng.uniform(0.02, 0.09, 3), rng.uniform(0.002, 0.015, 3)
        if not (R[0] + R[1] < 0.9 * L[0] and R[1] + R[2] < 0.9 * L[1]):
            continue
        out.append(
            FingerGeometry(
                link_lengths_m=tuple(L),  # type: ignore[arg-type]
                guide_radii_m=tuple(R),  # type: ignore[arg-type]
                tendon_diameter_m=float(rng.uniform(5e-4, 1.5e-3)),
                tendon_youngs_modulus_pa=float(rng.uniform(50e9, 250e9)),
                actuating_tendon_length_m=float(rng.uniform(0.03, 0.3)),
                link_masses_kg=tuple(rng.uniform(0, 0.05, 3)),  # type: ignore[arg-type]
                link_com_fraction=tuple(rng.uniform(0, 1, 3)),  # type: ignore[arg-type]
            )
        )
    return out


def stress(n: int = 400, load_scale: float = 4.0, seed: int = 1) -> dict[str, Any]:
    """Convergence within the default 100 passes, per relaxation, on random fingers under
    loads whose stretch turns the joints by about 0.15 rad x ``load_scale`` (threshold 1e-12)."""
    rng = np.random.default_rng(seed)
    counts = {rx: {"converged": 0, "passes": 0} for rx in statics.RELAXATIONS}
    for g in random_fingers(n, seed):
        ea = g.tendon_youngs_modulus_pa * g.tendon_area_m2
        f = 0.15 * load_scale * ea * min(g.guide_radii_m) ** 2
        f /= 3 * g.total_length_m * tendons.rest_lengths(g).max()
        a = rng.uniform(-np.pi, np.pi)
        load = Load(
            tip_force_n=(f * np.cos(a), f * np.sin(a)),
            tip_moment_nm=float(rng.uniform(-1, 1) * f * g.total_length_m / 3),
        )
        q = float(rng.uniform(*g.q_range_m))
        for rx in statics.RELAXATIONS:
            r = statics.solve(g, q, load, threshold_m=1e-12, relaxation=rx)
            counts[rx]["converged"] += int(r.converged)
            counts[rx]["passes"] += r.iterations
    return {"cases": n, "load_scale": load_scale, "results": counts}


def mujoco_hand(repeats: int = 2000) -> dict[str, Any]:
    """The MuJoCo hand's costs: building it, a step of the whole hand at its own timestep
    (fingers at rest under gravity, motors braked), a finger's equilibrium, a picture."""
    import mujoco

    from utrf.models import mjcf, mjcf_statics, render

    t_build = _median_time(mjcf.hand_model, 5)
    model = mjcf.hand_model()
    data = mujoco.MjData(model)
    hand = HandGeometry.default()
    mjcf.set_coupled_pose(model, data, {f.name: 0.005 for f in hand.fingers}, hand)
    t_step = _median_time(lambda: mujoco.mj_step(model, data), repeats)
    load = Load(payload_kg=0.5)
    t_eq = _median_time(lambda: mjcf_statics.equilibrium(model, "index", 0.0, load, hand), 30)
    out: dict[str, Any] = {
        "mujoco": mujoco.__version__,
        "nv": int(model.nv),
        "timestep_s": float(model.opt.timestep),
        "integrator": mujoco.mjtIntegrator(model.opt.integrator).name,
        "build_s": t_build,
        "step_s": t_step,
        "equilibrium_s": t_eq,
    }
    try:
        out["render_640x480_s"] = _median_time(lambda: render.render(model, data), 5)
        out["render_backend"] = render.gl_backend()
    except render.RenderError as exc:
        out["render_error"] = str(exc)
    return out


def run(
    batch_size: int = 10_000,
    repeats_one: int = 3000,
    repeats_batch: int = 7,
    stress_cases: int = 400,
) -> dict[str, Any]:
    geom = FingerGeometry.default()
    load = Load(payload_kg=3.0)
    out: dict[str, Any] = {
        "machine": {
            "cpu": cpu_name(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
        },
        "models": {},
    }
    cases = random_cases(geom, batch_size)

    def solve_cases(**options: Any) -> statics.StaticsBatch:
        """The random cases in one vectorised solve."""
        return statics.solve_batch(
            geom,
            cases["q"],
            payload_kg=cases["payload_kg"],
            tip_force_n=cases["tip_force_n"],
            tip_moment_nm=cases["tip_moment_nm"],
            **options,
        )

    for model in statics.MODELS:
        one = _median_time(lambda m=model: statics.solve(geom, 0.0, load, model=m), repeats_one)
        one_cpu = _cpu_time(lambda m=model: statics.solve(geom, 0.0, load, model=m), repeats_one)
        # The same case through the general path: measured in the same run, so the ratio
        # (why the fast path stays separate) holds whatever the machine's load.
        one_via_batch = _median_time(
            lambda m=model: statics.solve_batch(geom, [0.0], payload_kg=3.0, model=m),
            max(repeats_one // 10, 1),
        )
        res = statics.solve(geom, 0.0, load, model=model)

        def batch(m: str = model) -> statics.StaticsBatch:
            return solve_cases(model=m)

        t_batch = _median_time(batch, repeats_batch)
        t_batch_cpu = _cpu_time(batch, repeats_batch)
        b = batch()
        iters = [
            statics.solve(geom, 0.0, load, model=model, threshold_m=thr).iterations
            for thr in THRESHOLDS_M
        ]
        batch_iters = {
            f"{thr:g}": {
                "mean": float(solve_cases(model=model, threshold_m=thr).iterations.mean()),
            }
            for thr in (1e-6, 1e-9, 1e-12)
        }
        out["models"][model] = {
            "one_solve_s": one,
            "one_solve_cpu_s": one_cpu,
            "one_solve_via_batch_s": one_via_batch,
            "one_solve_iterations": res.iterations,
            "batch_size": batch_size,
            "batch_s": t_batch,
            "batch_solves_per_s": batch_size / t_batch,
            "batch_cpu_s": t_batch_cpu,
            "batch_solves_per_cpu_s": batch_size / t_batch_cpu,
            "one_by_one_solves_per_s": 1.0 / one,
            "batch_converged": int(b.converged.sum()),
            "batch_iterations_mean": float(b.iterations.mean()),
            "batch_iterations_max": int(b.iterations.max()),
            "iterations_vs_threshold_3kg_straight": dict(
                zip((f"{t:g}" for t in THRESHOLDS_M), iters, strict=True)
            ),
            "batch_iterations_vs_threshold": batch_iters,
        }
    # Relaxation: the same 10,000 cases, serial model, at 1e-9 m.
    out["relaxation"] = {}
    for rx in statics.RELAXATIONS:

        def relaxed(r: str = rx) -> statics.StaticsBatch:
            return solve_cases(relaxation=r)

        b = relaxed()
        out["relaxation"][rx] = {
            "batch_s": _median_time(relaxed, repeats_batch),
            "iterations_mean": float(b.iterations.mean()),
            "iterations_max": int(b.iterations.max()),
            "converged": int(b.converged.sum()),
        }
    out["stress"] = stress(stress_cases)
    out["mujoco_hand"] = mujoco_hand()
    if hasattr(os, "getloadavg"):
        out["load_average"] = os.getloadavg()[0]
    return out


def _via_batch(r: dict[str, Any]) -> str:
    t = r["one_solve_via_batch_s"]
    return f"{t * 1e6:.0f} µs ({t / r['one_solve_s']:.0f} times the fast path)"


def markdown(result: dict[str, Any]) -> str:
    m = result["machine"]
    s, p = result["models"]["serial"], result["models"]["printed"]
    n = s["batch_size"]
    lines = [
        "## Models",
        "",
        f"Measured with `{COMMAND}` on {m['cpu']} ({m['cores']} cores), Python {m['python']}, "
        f"numpy {m['numpy']}, scipy {m['scipy']}. Default finger, threshold 1e-9 m unless "
        "stated. Times are medians of repeated runs"
        + (
            f" (load average {result['load_average']:.1f} on the machine while measuring)."
            if "load_average" in result
            else "."
        ),
        "",
        "`statics.solve` runs the passes' fast path (`statics_passes.passes_one`: one case on "
        "plain floats, the general path's passes bit for bit); `statics.solve_batch` the general "
        "path (`statics_passes.passes`, numpy over the cases); targets (issue 11 goal 6): one "
        "solve at most 20 µs, the batch at least 200,000 solves/s. On the shared 2-core "
        "machine the wall-clock figures move with the other jobs' load: a call of some µs is "
        "rarely interrupted, a batch of tens of ms often is, so the "
        "CPU time (`time.process_time`: time spent waiting for a core left out) is given too.",
        "",
        "| figure | serial (default) | printed |",
        "|---|---|---|",
        f"| one statics solve (3 kg, straight), `statics.solve` | {s['one_solve_s'] * 1e6:.0f} µs "
        f"({s['one_solve_iterations']} iterations) | {p['one_solve_s'] * 1e6:.0f} µs "
        f"({p['one_solve_iterations']} iterations) |",
        f"| the same, CPU time per solve | {s['one_solve_cpu_s'] * 1e6:.1f} µs | "
        f"{p['one_solve_cpu_s'] * 1e6:.1f} µs |",
        f"| the same case through the general path (`solve_batch`), same run | "
        f"{_via_batch(s)} | {_via_batch(p)} |",
        f"| batch of {n:,} random load cases, `statics.solve_batch` | "
        f"{s['batch_s'] * 1e3:.1f} ms | {p['batch_s'] * 1e3:.1f} ms |",
        f"| solves per second, batched | {s['batch_solves_per_s']:,.0f} | "
        f"{p['batch_solves_per_s']:,.0f} |",
        f"| the batch, CPU time (solves per CPU second) | {s['batch_cpu_s'] * 1e3:.1f} ms "
        f"({s['batch_solves_per_cpu_s']:,.0f}) | {p['batch_cpu_s'] * 1e3:.1f} ms "
        f"({p['batch_solves_per_cpu_s']:,.0f}) |",
        f"| solves per second, one by one | {s['one_by_one_solves_per_s']:,.0f} | "
        f"{p['one_by_one_solves_per_s']:,.0f} |",
        f"| batch: converged / iterations mean, max | {s['batch_converged']:,} / "
        f"{s['batch_iterations_mean']:.2f}, {s['batch_iterations_max']} | "
        f"{p['batch_converged']:,} / {p['batch_iterations_mean']:.2f}, "
        f"{p['batch_iterations_max']} |",
        "",
        "Random cases: q uniform over the tendon's range, payload 0-3 kg, tip force ±10 N per "
        "axis, tip moment ±0.2 N m, link gravity on.",
        "",
        "Iterations of Algorithm 1 against its threshold (tip movement between two passes):",
        "",
        "| threshold (m) | serial, 3 kg straight | printed, 3 kg straight |",
        "|---|---|---|",
    ]
    for thr, it in s["iterations_vs_threshold_3kg_straight"].items():
        lines.append(f"| {thr} | {it} | {p['iterations_vs_threshold_3kg_straight'][thr]} |")
    lines += [
        "",
        f"Mean iterations over the {n:,} random cases: "
        + "; ".join(
            f"threshold {thr} m: serial {s['batch_iterations_vs_threshold'][thr]['mean']:.2f}, "
            f"printed {p['batch_iterations_vs_threshold'][thr]['mean']:.2f}"
            for thr in s["batch_iterations_vs_threshold"]
        )
        + ".",
        "",
        "Relaxation (`relaxation=`), serial model, the same cases at 1e-9 m: `none` is the "
        "paper's plain iteration, `auto` (default) switches a case to Aitken relaxation when its "
        "tip movement shrinks by less than half per pass, `aitken` relaxes every case.",
        "",
        "| relaxation | batch time | iterations mean, max | converged |",
        "|---|---|---|---|",
    ]
    for rx, r in result["relaxation"].items():
        lines.append(
            f"| {rx} | {r['batch_s'] * 1e3:.1f} ms | {r['iterations_mean']:.2f}, "
            f"{r['iterations_max']} | {r['converged']:,} |"
        )
    st = result["stress"]
    lines += [
        "",
        f"Stress: {st['cases']} random fingers (the tests' ranges) under loads "
        f"{st['load_scale']:g} times the tests' moderate size, threshold 1e-12 m, "
        "default 100-pass limit: converged "
        + ", ".join(
            f"`{rx}` {r['converged']}/{st['cases']} (mean {r['passes'] / st['cases']:.1f} passes)"
            for rx, r in st["results"].items()
        )
        + ".",
        "",
    ]
    mj = result.get("mujoco_hand")
    if mj:
        lines += [
            f"MuJoCo hand (`utrf.models.mjcf`, MuJoCo {mj['mujoco']}, {mj['nv']} degrees of "
            f"freedom, {mj['integrator']} at {mj['timestep_s'] * 1e3:g} ms):",
            "",
            "| figure | time |",
            "|---|---|",
            f"| build the model (`mjcf.hand_model`) | {mj['build_s'] * 1e3:.1f} ms |",
            f"| one step of the whole hand (`mj_step`) | {mj['step_s'] * 1e6:.1f} µs |",
            f"| one finger's equilibrium in MuJoCo (`mjcf_statics.equilibrium`, 0.5 kg) | "
            f"{mj['equilibrium_s'] * 1e3:.2f} ms |",
        ]
        if "render_640x480_s" in mj:
            lines.append(
                f"| one 640x480 picture off-screen (`render.render`, {mj['render_backend']}) | "
                f"{mj['render_640x480_s'] * 1e3:.0f} ms |"
            )
        else:
            lines.append(f"| picture | not measured: {mj['render_error']} |")
        lines.append("")
    return "\n".join(lines)


def update_section(path: Path, section: str) -> None:
    """Replace the "## Models" section of ``path`` (or append it); keep everything else."""
    write_section(path, section, "## Models")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tools.bench_models", description=(__doc__ or "").split("\n")[0]
    )
    parser.add_argument("--update", type=Path, help="Markdown file whose Models section to write")
    parser.add_argument("--json", type=Path, help="write the raw results here")
    parser.add_argument("--batch-size", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3000, help="repeats of the single solve")
    parser.add_argument("--stress-cases", type=int, default=400)
    args = parser.parse_args(argv)
    if min(args.batch_size, args.repeats, args.stress_cases) < 1:
        parser.error("--batch-size, --repeats and --stress-cases must be >= 1")
    result = run(args.batch_size, args.repeats, stress_cases=args.stress_cases)
    section = markdown(result)
    print(section)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    if args.update:
        update_section(args.update, section)
        print(f"updated the Models section of {args.update}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
