"""Workspace of a UTRF finger (paper Sec. II-C, Fig. 3): the areas swept by Links 1-3.

Link k at tendon displacement q occupies the segment from Joint k along its absolute angle
φ_k = q c_k for a length s in [0, L_k] (the paper sweeps each L_i from zero to its nominal
value). Sweeping q over the tendon's range gives each link's swept area. The areas are
rasterised: the segments are sampled at most half a cell apart along s and along q (the q
step is chosen from the largest speed of the link's end, Σ_{i<=k} L_i c_i), and every cell
holding a sample counts. A cell cut by the boundary counts whole, so a raster area errs high
by at most the perimeter times one cell width; the error is linear in the cell width, so
``areas`` extrapolates from two widths (Richardson) to an estimate independent of the grid.

Like the paper, the model ignores collisions between links.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from utrf.models import kinematics
from utrf.models.geometry import FingerGeometry

DEFAULT_RESOLUTION_M = 2.5e-4
_CHUNK_POINTS = 2_000_000


@dataclass(frozen=True)
class Workspace:
    resolution_m: float
    extent_m: tuple[float, float, float, float]  # x_min, x_max, y_min, y_max
    masks: np.ndarray  # (3, ny, nx) bool: cells swept by Link 1, 2, 3
    q_range_m: tuple[float, float]

    @property
    def cell_area_m2(self) -> float:
        return self.resolution_m**2

    @property
    def link_areas_m2(self) -> np.ndarray:
        return self.masks.reshape(3, -1).sum(axis=1) * self.cell_area_m2

    @property
    def overlap_12_m2(self) -> float:
        """Area swept by both Link 1 and Link 2 (the paper's dark red)."""
        return float((self.masks[0] & self.masks[1]).sum() * self.cell_area_m2)

    @property
    def total_area_m2(self) -> float:
        return float(self.masks.any(axis=0).sum() * self.cell_area_m2)

    def contains(self, points: np.ndarray, link: int) -> np.ndarray:
        """Whether each point (..., 2) lies in a cell swept by ``link`` (1, 2 or 3)."""
        p = np.asarray(points, dtype=float)
        ix, iy, inside = self._cells(p)
        out = np.zeros(p.shape[:-1], dtype=bool)
        out[inside] = self.masks[link - 1][iy[inside], ix[inside]]
        return out

    def _cells(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x0, _, y0, _ = self.extent_m
        ny, nx = self.masks.shape[1:]
        ix = np.floor((p[..., 0] - x0) / self.resolution_m).astype(int)
        iy = np.floor((p[..., 1] - y0) / self.resolution_m).astype(int)
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        return ix, iy, inside

    def to_json(self) -> dict[str, Any]:
        return {
            "resolution_m": self.resolution_m,
            "q_range_m": list(self.q_range_m),
            "link_areas_m2": self.link_areas_m2.tolist(),
            "overlap_12_m2": self.overlap_12_m2,
            "total_area_m2": self.total_area_m2,
            "area_error_bound_note": "each area errs high by at most perimeter x resolution",
        }


def swept(
    geom: FingerGeometry,
    resolution_m: float = DEFAULT_RESOLUTION_M,
    q_range: tuple[float, float] | None = None,
) -> Workspace:
    """Rasterised areas swept by Links 1-3 over ``q_range`` (default: the tendon's range)."""
    if not (math.isfinite(resolution_m) and 0 < resolution_m <= geom.total_length_m / 10):
        raise ValueError(
            f"resolution_m must be > 0 and at most a tenth of the finger "
            f"({geom.total_length_m / 10:g} m), got {resolution_m!r}"
        )
    lo, hi = q_range if q_range is not None else geom.q_range_m
    if not lo < hi:
        raise ValueError(f"q_range must be (min, max) with min < max, got {(lo, hi)}")
    reach = geom.total_length_m + 2 * resolution_m
    nx = ny = math.ceil(2 * reach / resolution_m)
    extent = (-reach, -reach + nx * resolution_m, -reach, -reach + ny * resolution_m)
    masks = np.zeros((3, ny, nx), dtype=bool)
    c = np.cumsum(1.0 / geom.R)
    half = resolution_m / 2
    for k in range(3):
        speed = float(np.sum(geom.L[: k + 1] * c[: k + 1]))  # bound on |d(link end)/dq|
        n_q = max(2, math.ceil((hi - lo) * speed / half) + 1)
        n_s = max(2, math.ceil(geom.L[k] / half) + 1)
        s = np.linspace(0.0, geom.L[k], n_s)
        q_all = np.linspace(lo, hi, n_q)
        per_chunk = max(1, _CHUNK_POINTS // n_s)
        for start in range(0, n_q, per_chunk):
            q = q_all[start : start + per_chunk]
            pts = kinematics.joint_positions(geom, q)  # (nq, 4, 2)
            phi = q * c[k]
            base = pts[:, k, :]
            x = base[:, 0:1] + s[None, :] * np.cos(phi)[:, None]
            y = base[:, 1:2] + s[None, :] * np.sin(phi)[:, None]
            ix = np.floor((x - extent[0]) / resolution_m).astype(np.intp).ravel()
            iy = np.floor((y - extent[2]) / resolution_m).astype(np.intp).ravel()
            masks[k][iy, ix] = True
    return Workspace(
        resolution_m=resolution_m, extent_m=extent, masks=masks, q_range_m=(float(lo), float(hi))
    )


@dataclass(frozen=True)
class Areas:
    """Swept areas (m²) extrapolated to a zero cell width from rasters at h and 2h."""

    resolution_m: float
    link_areas_m2: np.ndarray  # (3,)
    overlap_12_m2: float
    total_area_m2: float
    raster_link_areas_m2: np.ndarray  # (3,) at resolution_m, before extrapolation

    def to_json(self) -> dict[str, Any]:
        return {
            "resolution_m": self.resolution_m,
            "link_areas_m2": self.link_areas_m2.tolist(),
            "overlap_12_m2": self.overlap_12_m2,
            "total_area_m2": self.total_area_m2,
            "raster_link_areas_m2": self.raster_link_areas_m2.tolist(),
        }


def areas(
    geom: FingerGeometry,
    resolution_m: float = DEFAULT_RESOLUTION_M,
    q_range: tuple[float, float] | None = None,
    fine: Workspace | None = None,
) -> Areas:
    """Swept areas, Richardson-extrapolated: A ≈ 2 A(h) − A(2h). ``fine`` reuses a raster at h."""
    ws = fine if fine is not None else swept(geom, resolution_m, q_range)
    coarse = swept(geom, 2 * ws.resolution_m, ws.q_range_m)

    def extrapolate(a: float | np.ndarray, b: float | np.ndarray) -> np.ndarray:
        return np.maximum(2 * np.asarray(a) - np.asarray(b), 0.0)

    return Areas(
        resolution_m=ws.resolution_m,
        link_areas_m2=extrapolate(ws.link_areas_m2, coarse.link_areas_m2),
        overlap_12_m2=float(extrapolate(ws.overlap_12_m2, coarse.overlap_12_m2)),
        total_area_m2=float(extrapolate(ws.total_area_m2, coarse.total_area_m2)),
        raster_link_areas_m2=ws.link_areas_m2,
    )


# Colours of the paper's Fig. 3: Link 3 blue, Link 2 yellow, Link 1 red, Links 1 and 2 dark red.
_COLOURS = {
    "link3": (0.22, 0.42, 0.85),
    "link2": (0.98, 0.82, 0.22),
    "link1": (0.90, 0.25, 0.20),
    "overlap12": (0.50, 0.02, 0.06),
}


def plot(
    ws: Workspace,
    geom: FingerGeometry,
    out: str | Path,
    *,
    postures: int = 7,
    extrapolated: Areas | None = None,
) -> Path:
    """A figure like the paper's Fig. 3, with a few finger postures drawn over it (mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    m1, m2, m3 = ws.masks
    img = np.ones((*m1.shape, 3))
    img[m3] = _COLOURS["link3"]
    img[m2] = _COLOURS["link2"]
    img[m1] = _COLOURS["link1"]
    img[m1 & m2] = _COLOURS["overlap12"]
    # Crop to the swept cells, with a margin.
    rows = np.flatnonzero(ws.masks.any(axis=(0, 2)))
    cols = np.flatnonzero(ws.masks.any(axis=(0, 1)))
    pad = max(1, int(0.005 / ws.resolution_m))
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad, m1.shape[0] - 1)
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad, m1.shape[1] - 1)
    x0, _, y0, _ = ws.extent_m
    res = ws.resolution_m
    extent_mm = np.array([x0 + c0 * res, x0 + (c1 + 1) * res, y0 + r0 * res, y0 + (r1 + 1) * res])
    fig, ax = plt.subplots(figsize=(5.0, 5.0), dpi=100)
    ax.imshow(
        img[r0 : r1 + 1, c0 : c1 + 1],
        origin="lower",
        extent=tuple(extent_mm * 1e3),
        interpolation="nearest",
    )
    for q in np.linspace(*ws.q_range_m, postures):
        pts = kinematics.joint_positions(geom, q) * 1e3
        ax.plot(pts[:, 0], pts[:, 1], "-o", color="k", lw=0.8, ms=2)
    a = extrapolated if extrapolated is not None else areas(geom, fine=ws)
    mm2 = a.link_areas_m2 * 1e6
    ax.legend(
        handles=[
            Patch(color=_COLOURS["link1"], label=f"Link 1 ({mm2[0]:.0f} mm²)"),
            Patch(color=_COLOURS["link2"], label=f"Link 2 ({mm2[1]:.0f} mm²)"),
            Patch(color=_COLOURS["link3"], label=f"Link 3 ({mm2[2]:.0f} mm²)"),
            Patch(
                color=_COLOURS["overlap12"],
                label=f"Links 1 and 2 ({a.overlap_12_m2 * 1e6:.0f} mm²)",
            ),
        ],
        fontsize=7,
        loc="lower left",
    )
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(
        f"Workspace, L = {[round(v * 1e3, 1) for v in geom.link_lengths_m]} mm, "
        f"R = {[round(v * 1e3, 1) for v in geom.guide_radii_m]} mm",
        fontsize=9,
    )
    ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
