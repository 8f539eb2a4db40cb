"""Tip deflection against payload at the straight horizontal pose (paper Sec. IV-A, Fig. 8).

The experiment zeroes the tracker on the finger as it stands without a payload (its links'
weight already on it), then hangs 0.5-3 kg at the tip. So the deflection here is the tip's
distance from the zero-payload equilibrium, gravity on in both. Stiffness is reported two
ways: the secant at the largest load (the paper's 3 x 9.81 / 0.024386 = 1.21e3 N/m) and the
least-squares slope of force against deflection through the origin.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from utrf.models import statics
from utrf.models.geometry import FingerGeometry

PAPER_LOAD_KG = 3.0
PAPER_DEFLECTION_M = 0.024386
PAPER_STIFFNESS_N_PER_M = PAPER_LOAD_KG * statics.GRAVITY_MPS2 / PAPER_DEFLECTION_M
PAPER_LOADS_KG = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)


@dataclass(frozen=True)
class DeflectionCurve:
    model: str
    q_m: float
    loads_kg: np.ndarray
    deflection_m: np.ndarray  # distance from the zero-payload tip
    vertical_m: np.ndarray  # downward component of the same displacement
    tensions_n: np.ndarray  # (n, 3)
    iterations: np.ndarray

    @property
    def forces_n(self) -> np.ndarray:
        return self.loads_kg * statics.GRAVITY_MPS2

    @property
    def secant_stiffness_n_per_m(self) -> float:
        """Force over deflection at the largest load (the paper's figure of merit)."""
        i = int(np.argmax(self.loads_kg))
        return float(self.forces_n[i] / self.deflection_m[i])

    @property
    def fit_stiffness_n_per_m(self) -> float:
        """Least-squares slope of force against deflection, through the origin."""
        d, f = self.deflection_m, self.forces_n
        return float((d @ f) / (d @ d))

    def at(self, load_kg: float) -> float:
        """Deflection (m) at one of the curve's loads."""
        hits = np.flatnonzero(np.isclose(self.loads_kg, load_kg))
        if hits.size == 0:
            raise KeyError(f"load {load_kg} kg is not on the curve {self.loads_kg.tolist()}")
        return float(self.deflection_m[hits[0]])

    def to_json(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "q_m": self.q_m,
            "loads_kg": self.loads_kg.tolist(),
            "deflection_m": self.deflection_m.tolist(),
            "vertical_deflection_m": self.vertical_m.tolist(),
            "tensions_n": self.tensions_n.tolist(),
            "stiffness_n_per_m": self.secant_stiffness_n_per_m,
            "fit_stiffness_n_per_m": self.fit_stiffness_n_per_m,
        }


def deflection_curve(
    geom: FingerGeometry,
    loads_kg: ArrayLike = PAPER_LOADS_KG,
    *,
    q: float = 0.0,
    model: str = statics.DEFAULT_MODEL,
    gravity: bool = True,
) -> DeflectionCurve:
    loads = np.atleast_1d(np.asarray(loads_kg, dtype=float))
    if loads.ndim != 1 or loads.size == 0 or np.any(loads <= 0) or not np.all(np.isfinite(loads)):
        raise statics.StaticsError(f"loads_kg must be positive finite masses, got {loads_kg!r}")
    batch = statics.solve_batch(
        geom, q, payload_kg=np.concatenate([[0.0], loads]), gravity=gravity, model=model
    )
    if not batch.converged.all():
        raise statics.StaticsError("statics did not converge for every load of the curve")
    disp = batch.tip[1:] - batch.tip[0]
    return DeflectionCurve(
        model=model,
        q_m=q,
        loads_kg=loads,
        deflection_m=np.hypot(disp[:, 0], disp[:, 1]),
        vertical_m=-disp[:, 1],
        tensions_n=batch.tensions_n[1:],
        iterations=batch.iterations[1:],
    )


def plot(
    curves: Sequence[DeflectionCurve],
    out: str | Path,
    *,
    labels: Sequence[str] | None = None,
    title: str = "Tip deflection at the straight horizontal pose",
) -> Path:
    """Deflection (mm) against payload (kg), with the paper's reported 3 kg point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.2, 3.6), dpi=110)
    styles = ["o-", "s--", "^-.", "d:"]
    for i, c in enumerate(curves):
        label = labels[i] if labels else f"{c.model} model"
        ax.plot(
            np.concatenate([[0.0], c.loads_kg]),
            np.concatenate([[0.0], c.deflection_m]) * 1e3,
            styles[i % len(styles)],
            ms=4,
            label=f"{label}: {c.secant_stiffness_n_per_m:.3g} N/m",
        )
    ax.plot(
        [PAPER_LOAD_KG],
        [PAPER_DEFLECTION_M * 1e3],
        "k*",
        ms=11,
        label=f"paper, measured: {PAPER_DEFLECTION_M * 1e3:.3f} mm at 3 kg "
        f"({PAPER_STIFFNESS_N_PER_M:.3g} N/m)",
    )
    ax.set_xlabel("tip payload (kg)")
    ax.set_ylabel("tip deflection (mm)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
