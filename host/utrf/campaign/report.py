"""What a campaign found, from its Parquet results alone (``utrf campaign report DIR``).

Every kind: runs done, failed and why. Designs: the Pareto front of the campaign's objectives
among the designs the planner accepts (``plan_safe``), as a table and a picture. Grasps: the
success rate (held, not broken) per value of each parameter with a Wilson interval, a map
over two parameters, and, for two firmwares, the A/B verdict: the difference in success rate
over the same scenarios, paired, with its confidence interval and McNemar's exact test.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from utrf.campaign import spec
from utrf.campaign.store import Store

Z95 = 1.959963984540054
FRONT_ROWS = 10


def _dominated(by: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """For each of ``rows`` (m, k): whether some row of ``by`` (f, k) is no worse in every
    objective and better in one (all minimised)."""
    no_worse = np.all(by[None, :, :] <= rows[:, None, :], axis=-1)
    better = np.any(by[None, :, :] < rows[:, None, :], axis=-1)
    return np.asarray(np.any(no_worse & better, axis=1))


def pareto_front(values: np.ndarray, senses: list[str]) -> np.ndarray:
    """Indices of the non-dominated rows of ``values`` (n, k) ("max"/"min" per column), in
    blocks so a million rows fit in memory; ties are kept."""
    v = np.where(np.array([s == "max" for s in senses])[None, :], -values, values)  # minimise
    order = np.argsort(v[:, 0], kind="stable")
    front = np.zeros((0, v.shape[1]))
    front_idx = np.zeros(0, dtype=np.intp)
    for start in range(0, len(order), 2048):
        idx = order[start : start + 2048]
        block = v[idx]
        if len(front):  # drop what the front so far dominates
            keep = ~_dominated(front, block)
            idx, block = idx[keep], block[keep]
        if not len(idx):
            continue
        keep = ~_dominated(block, block)
        idx, block = idx[keep], block[keep]
        if len(front):  # the block's survivors may beat points of the front
            stay = ~_dominated(block, front)
            front, front_idx = front[stay], front_idx[stay]
        front = np.concatenate([front, block])
        front_idx = np.concatenate([front_idx, idx])
    return np.sort(front_idx)


def wilson(successes: int, n: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of a proportion."""
    if n == 0:
        return (math.nan, math.nan)
    p = successes / n
    den = 1 + Z95**2 / n
    mid = (p + Z95**2 / (2 * n)) / den
    half = Z95 * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n)) / den
    return (mid - half, mid + half)


def paired_difference(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """B's success rate minus A's over the same scenarios (bool arrays, paired): the mean
    difference with a 95 % interval (Student's t on the paired differences) and McNemar's
    exact p-value (a binomial test on the discordant pairs)."""
    from scipy import stats

    d = b.astype(float) - a.astype(float)
    n = len(d)
    mean = float(d.mean()) if n else math.nan
    if n > 1 and d.std(ddof=1) > 0:
        half = float(stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / math.sqrt(n))
    else:
        half = 0.0 if n > 1 else math.nan
    only_a, only_b = int(((a) & ~b).sum()), int((~a & b).sum())
    p = stats.binomtest(only_b, only_a + only_b).pvalue if only_a + only_b else 1.0
    return {
        "scenarios": n,
        "difference": mean,
        "ci_low": mean - half,
        "ci_high": mean + half,
        "only_a_held": only_a,
        "only_b_held": only_b,
        "mcnemar_p": float(p),
    }


def _column(table: pa.Table, name: str) -> np.ndarray:
    return np.asarray(table.column(name).to_pylist(), dtype=object)


def report(root: Path, *, plots: bool = True) -> dict[str, Any]:
    """The campaign's findings as a dict (also written to ``report.json`` and ``report.md``)."""
    store = Store(root)
    campaign = spec.parse((root / "campaign.toml").read_text(), str(root / "campaign.toml"))
    table = store.read()
    status = _column(table, "status") if "status" in table.column_names else np.zeros(0)
    failed = status != "ok"
    reasons = Counter(_column(table, "error")[failed].tolist()) if failed.any() else Counter()
    out: dict[str, Any] = {
        "campaign": campaign.name,
        "kind": campaign.kind,
        "runs": int(table.num_rows),
        "ok": int((~failed).sum()),
        "failed": int(failed.sum()),
        "failure_reasons": reasons.most_common(5),
    }
    if table.num_rows and campaign.kind == "design":
        out["design"] = _designs(campaign, table, root, plots)
    if table.num_rows and campaign.kind == "grasp":
        from utrf.campaign.grasp_report import grasps

        out["grasp"] = grasps(campaign, table, root, plots)
    store.consolidate()
    (root / "report.json").write_text(json.dumps(out, indent=2, default=str) + "\n")
    (root / "report.md").write_text(describe(out) + "\n")
    return out


def _designs(campaign: spec.Campaign, table: pa.Table, root: Path, plots: bool) -> dict:
    names = list(campaign.objectives) or ["link3_area_m2", "stiffness_straight_n_per_m"]
    senses = [campaign.objectives.get(n, "max") for n in names]
    ok = np.asarray(table.column("status").to_numpy(zero_copy_only=False)) == "ok"
    safe = ok & np.asarray(
        table.column("plan_safe").fill_null(False).to_numpy(zero_copy_only=False), dtype=bool
    )
    values = np.column_stack(
        [
            np.asarray(
                table.column(n).fill_null(np.nan).to_numpy(zero_copy_only=False), dtype=float
            )
            for n in names
        ]
    )
    finite = safe & np.isfinite(values).all(1)
    cand = np.flatnonzero(finite)
    front = cand[pareto_front(values[cand], senses)]
    params = [p.name for p in campaign.params if not p.fixed]
    order = front[np.argsort(-values[front, 0] if senses[0] == "max" else values[front, 0])]
    rows = table.take(pa.array(order[:FRONT_ROWS])).select(["run_key", *params, *names])
    out = {
        "objectives": dict(zip(names, senses, strict=True)),
        "designs": int(ok.sum()),
        "plan_safe": int(safe.sum()),
        "front_size": len(front),
        "front": rows.to_pylist(),
    }
    if plots and len(names) >= 2:
        out["picture"] = str(_front_plot(values, finite, front, names, root / "front.png"))
    return out


def _front_plot(
    values: np.ndarray, feasible: np.ndarray, front: np.ndarray, names: list[str], path: Path
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(0)
    cloud = np.flatnonzero(feasible)
    if len(cloud) > 20_000:
        cloud = rng.choice(cloud, 20_000, replace=False)
    fig, ax = plt.subplots(figsize=(6, 4.5), dpi=100)
    ax.scatter(values[cloud, 0], values[cloud, 1], s=2, c="0.75", label="accepted designs")
    f = front[np.argsort(values[front, 0])]
    ax.scatter(values[f, 0], values[f, 1], s=10, c="C3", label=f"Pareto front ({len(front)})")
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.legend(fontsize=8)
    extra = len(names) - 2
    ax.set_title(
        f"{feasible.sum()} designs the planner accepts"
        + (f"; the front of {len(names)} objectives, seen on the first two" if extra else ""),
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def describe(out: dict[str, Any]) -> str:
    lines = [
        f"campaign {out['campaign']} ({out['kind']}): {out['runs']} runs, {out['ok']} ok, "
        f"{out['failed']} failed"
    ]
    for reason, count in out["failure_reasons"]:
        lines.append(f"  failed x{count}: {reason}")
    d = out.get("design")
    if d:
        objs = ", ".join(f"{k} ({v})" for k, v in d["objectives"].items())
        lines.append(
            f"designs: {d['designs']} evaluated, {d['plan_safe']} accepted by the "
            f"planner; Pareto front of {objs}: {d['front_size']} designs"
        )
        for r in d["front"]:
            lines.append("  " + "  ".join(f"{k}={_fmt(v)}" for k, v in r.items()))
        if d.get("picture"):
            lines.append(f"front: {d['picture']}")
    g = out.get("grasp")
    if g:
        from utrf.campaign.grasp_report import describe_grasps

        lines += describe_grasps(g)
    return "\n".join(lines)


def _fmt(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
