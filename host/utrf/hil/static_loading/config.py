"""A static loading run's configuration and the columns of the files it writes: what the run
writes and the analysis reads (``utrf.hil.static_loading``)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import read_rows
from utrf.hil.runs import RunError, finite_mean

PAPER_LOADS_KG = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
SAMPLE_COLUMNS = (
    "step",
    "attempt",
    "repeat",
    "load_kg",
    "time_s",
    "raw_x_m",
    "raw_y_m",
    "raw_z_m",
    "visible",
    "quality",
    "tip_x_m",
    "tip_y_m",
    "out_of_plane_m",
    "theta2_rad",
    "theta2_frames",
    "theta2_frames_sd_rad",
    "target_rad",
    "duty_a",
    "duty_b",
    "faults",
    "current_a_a",
    "current_b_a",
    "tracker_frame",
)
STEP_COLUMNS = (
    "step",
    "attempt",
    "repeat",
    "load_kg",
    "t_start_s",
    "t_end_s",
    "samples",
    "visible",
    "tip_x_m",
    "tip_y_m",
    "tip_sd_m",
    "theta2_rad",
    "theta2_sd_rad",
    "theta2_frames",
    "duty_a",
    "duty_b",
    "current_a_a",
)
REG_COLUMNS = (
    "pose",
    "theta2_rad",
    "model_x_m",
    "model_y_m",
    "raw_x_m",
    "raw_y_m",
    "raw_z_m",
    "samples",
)


@dataclass(frozen=True)
class StaticLoadingConfig:
    """A static loading run. SI units (the CLI converts)."""

    finger: int = 1
    loads_kg: tuple[float, ...] = PAPER_LOADS_KG
    repeats: int = 3
    theta2_rad: float = 0.0  # the held pose: straight
    settle_s: float = 1.5
    record_s: float = 1.0
    tracker_hz: float = 40.0
    #: the board's state stream during the run: every frame's Joint-2 reading is averaged
    telemetry_hz: int = 500
    registration_theta2_rad: tuple[float, ...] = (-0.35, 0.0, 0.35, 0.7)
    force: bool = False
    actuator_rating_n: float | None = None  # None: the planner's default (Limits)
    settle_tolerance_rad: float = math.radians(2.0)
    emulated: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.finger <= 4:
            raise RunError(f"finger must be 0..4 (0 thumb .. 4 little), got {self.finger}")
        if not self.loads_kg:
            raise RunError("loads_kg: give at least one payload")
        for w in self.loads_kg:
            if not (math.isfinite(w) and 0 < w <= 10):
                raise RunError(f"loads_kg: each payload must lie in (0, 10] kg, got {w}")
        if len(set(self.loads_kg)) != len(self.loads_kg):
            raise RunError(f"loads_kg: payloads listed twice: {list(self.loads_kg)}")
        if not 1 <= self.repeats <= 100:
            raise RunError(f"repeats must be 1..100, got {self.repeats}")
        for name in ("settle_s", "record_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise RunError(f"{name} must be > 0 s, got {v}")
        if not (math.isfinite(self.tracker_hz) and 1 <= self.tracker_hz <= 1000):
            raise RunError(f"tracker_hz must lie in [1, 1000], got {self.tracker_hz}")
        if not (isinstance(self.telemetry_hz, int) and 1 <= self.telemetry_hz <= 500):
            raise RunError(f"telemetry_hz must be an integer in [1, 500], got {self.telemetry_hz}")
        if self.record_s * self.tracker_hz < 3:
            raise RunError("record_s x tracker_hz must give at least 3 samples a step")
        if len(self.registration_theta2_rad) < 3:
            raise RunError("registration needs at least 3 poses")

    def schedule(self) -> list[tuple[int, int, float]]:
        """(step, repeat, load) in order: each repeat starts unloaded (its reference)."""
        out = []
        step = 0
        for r in range(self.repeats):
            for w in (0.0, *sorted(self.loads_kg)):
                out.append((step, r, w))
                step += 1
        return out

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["loads_kg"] = list(self.loads_kg)
        d["registration_theta2_rad"] = list(self.registration_theta2_rad)
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> StaticLoadingConfig:
        d = dict(d)
        d["loads_kg"] = tuple(d["loads_kg"])
        d["registration_theta2_rad"] = tuple(d["registration_theta2_rad"])
        return cls(**d)


def completed_steps(out: Path) -> dict[int, dict[str, Any]]:
    rows = read_rows(out / "steps.csv", STEP_COLUMNS)
    return {int(r["step"]): r for r in rows}


def frames_mean(theta2: np.ndarray, frames: np.ndarray) -> float:
    """A step's Joint-2 angle: the mean over every telemetry frame of its samples (each row
    holds its frames' mean), or over the rows where no frame came (telemetry off)."""
    th = np.asarray(theta2, dtype=float)
    w = np.asarray(frames, dtype=float)
    ok = np.isfinite(th)
    if not (w[ok] > 0).any():
        return finite_mean(th)
    return float((th[ok] * w[ok]).sum() / w[ok].sum())
