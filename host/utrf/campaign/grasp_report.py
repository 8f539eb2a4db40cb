"""A grasp campaign's findings: success (held and not broken) per parameter value with its
Wilson interval, a success map over two parameters, and the firmware A/B verdict."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from utrf.campaign.report import paired_difference, wilson
from utrf.campaign.spec import Campaign


def _success(table: pa.Table) -> tuple[np.ndarray, np.ndarray]:
    """(ran: the run finished, success: held and not broken) per row."""
    ok = np.asarray(table.column("status").to_pylist()) == "ok"
    held = (
        np.asarray([bool(v) for v in table.column("held").to_pylist()])
        if ("held" in table.column_names)
        else np.zeros(table.num_rows, bool)
    )
    broke = (
        np.asarray([bool(v) for v in table.column("broke").to_pylist()])
        if ("broke" in table.column_names)
        else np.zeros(table.num_rows, bool)
    )
    return ok, ok & held & ~broke


def grasps(campaign: Campaign, table: pa.Table, root: Path, plots: bool) -> dict[str, Any]:
    ran, success = _success(table)
    varied = [p.name for p in campaign.params if not p.fixed and p.name in table.column_names]
    per: dict[str, list[dict[str, Any]]] = {}
    for name in varied:
        col = _binned(np.asarray(table.column(name).to_pylist(), dtype=object))
        rows = []
        for value in sorted(set(col[ran].tolist()), key=str):
            sel = ran & (col == value)
            k, n = int(success[sel].sum()), int(sel.sum())
            lo, hi = wilson(k, n)
            rows.append(
                {
                    "value": value,
                    "runs": n,
                    "held": k,
                    "rate": k / n if n else None,
                    "ci_low": lo,
                    "ci_high": hi,
                }
            )
        per[name] = rows
    out: dict[str, Any] = {"runs": int(ran.sum()), "held": int(success.sum()), "by": per}
    if "firmware" in table.column_names and len(campaign.firmware) == 2:
        out["ab"] = _ab(campaign, table, ran, success, varied)
    # the map's axes: two varied numeric parameters (mass and friction, say), else the object
    numeric = [n for n in varied if n not in ("seed", "firmware", "object")]
    axes = (numeric + [n for n in varied if n == "object"])[:2]
    if plots and len(axes) == 2:
        out["picture"] = str(_map(table, ran, success, axes, root / "grasp_map.png"))
    return out


BINS = 4  # a sampled (continuous) parameter's table: its quartiles


def _binned(col: np.ndarray) -> np.ndarray:
    """A numeric column of many values (a random or Latin hypercube sample) as quartile
    ranges ("0.1-0.23"); lists of a few values stay as they are."""
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in col)
    if not numeric or len(set(col.tolist())) <= 2 * BINS:
        return col
    x = col.astype(float)
    edges = np.quantile(x, np.linspace(0, 1, BINS + 1))
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, BINS - 1)
    labels = [f"{edges[i]:.3g}-{edges[i + 1]:.3g}" for i in range(BINS)]
    return np.asarray([labels[i] for i in which], dtype=object)


def _ab(
    campaign: Campaign, table: pa.Table, ran: np.ndarray, success: np.ndarray, varied: list[str]
) -> dict[str, Any]:
    a_label, b_label = sorted(campaign.firmware)
    fw = np.asarray(table.column("firmware").to_pylist(), dtype=object)
    scenario_cols = [n for n in varied if n != "firmware"]
    keys = (
        list(zip(*(table.column(n).to_pylist() for n in scenario_cols), strict=True))
        if (scenario_cols)
        else [()] * table.num_rows
    )
    a: dict[Any, bool] = {}
    b: dict[Any, bool] = {}
    for i, key in enumerate(keys):
        if ran[i]:
            (a if fw[i] == a_label else b)[key] = bool(success[i])
    both = sorted(set(a) & set(b), key=str)
    verdict = paired_difference(
        np.array([a[k] for k in both], bool), np.array([b[k] for k in both], bool)
    )
    return {
        "a": a_label,
        "b": b_label,
        **verdict,
        "rate_a": float(np.mean([a[k] for k in both])) if both else None,
        "rate_b": float(np.mean([b[k] for k in both])) if both else None,
    }


def _map(
    table: pa.Table, ran: np.ndarray, success: np.ndarray, axes: list[str], path: Path
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = [np.asarray(table.column(n).to_pylist(), dtype=object) for n in axes]
    xs = sorted(set(cols[0][ran].tolist()), key=str)
    ys = sorted(set(cols[1][ran].tolist()), key=str)
    grid = np.full((len(ys), len(xs)), np.nan)
    counts = np.zeros_like(grid, dtype=int)
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            sel = ran & (cols[0] == x) & (cols[1] == y)
            if sel.any():
                grid[j, i], counts[j, i] = success[sel].mean(), sel.sum()
    fig, ax = plt.subplots(figsize=(1.2 + 0.9 * len(xs), 1.2 + 0.6 * len(ys)), dpi=100)
    im = ax.imshow(grid, origin="lower", cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    for j in range(len(ys)):
        for i in range(len(xs)):
            if counts[j, i]:
                ax.text(
                    i,
                    j,
                    f"{grid[j, i]:.0%}\nn={counts[j, i]}",
                    ha="center",
                    va="center",
                    fontsize=7,
                )
    ax.set_xticks(range(len(xs)), [f"{x:.3g}" if isinstance(x, float) else str(x) for x in xs])
    ax.set_yticks(range(len(ys)), [f"{y:.3g}" if isinstance(y, float) else str(y) for y in ys])
    ax.set_xlabel(axes[0])
    ax.set_ylabel(axes[1])
    ax.set_title("held (and not broken)", fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.05)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def describe_grasps(g: dict[str, Any]) -> list[str]:
    lines = [f"grasps: {g['held']} of {g['runs']} held (and did not break)"]
    for name, rows in g["by"].items():
        cells = [
            f"{_label(r['value'])}: {r['held']}/{r['runs']} ({r['ci_low']:.0%}-{r['ci_high']:.0%})"
            for r in rows
        ]
        lines.append(f"  by {name}: " + ", ".join(cells))
    ab = g.get("ab")
    if ab:
        lines.append(
            f"firmware A/B over {ab['scenarios']} paired scenarios: {ab['b']} minus {ab['a']} "
            f"= {ab['difference']:+.1%} held (95 % CI {ab['ci_low']:+.1%} to {ab['ci_high']:+.1%}"
            f"; McNemar p = {ab['mcnemar_p']:.3g}; held only by {ab['a']}: {ab['only_a_held']}, "
            f"only by {ab['b']}: {ab['only_b_held']})"
        )
    if g.get("picture"):
        lines.append(f"map: {g['picture']}")
    return lines


def _label(v: Any) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)
