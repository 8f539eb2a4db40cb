"""A grasp hold's configuration and the columns of the files it writes: what the run writes
and the analysis reads (``utrf.hil.grasp_hold``)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from utrf.hil.runs import RunError

FINGER_FIELDS = ("theta2_rad", "target_rad", "duty_a", "duty_b", "mode", "faults", "current_a_a")
HIT_COLUMNS = ("time_s", "finger", "impulse_x_ns", "impulse_y_ns", "duration_s")


def sample_columns(names: list[str]) -> list[str]:
    cols = ["time_s", "phase", "raw_x_m", "raw_y_m", "raw_z_m", "visible", "tracker_frame"]
    for n in names:
        cols += [f"{n}_{f}" for f in FINGER_FIELDS]
    return cols


def sample_row(t: float, phase: str, sample: Any, state: Any, currents: np.ndarray) -> list[object]:
    """One ``samples.csv`` row, field by field: the time, the phase, the tracker's ``sample``
    (position, visibility, frame), each finger of the hand's ``state`` (None: NaNs) and its
    motor A current (the general form :func:`sample_line` formats at once)."""
    row: list[object] = [
        f"{t:.6f}",
        phase,
        *(f"{v:.7f}" for v in sample.position_m),
        int(sample.visible),
        sample.frame,
    ]
    for i in range(len(currents)):
        if state is None:
            row += ["nan"] * len(FINGER_FIELDS)
            continue
        fs = state.fingers[i]
        row += [f"{fs.theta2:.5f}", f"{fs.target:.5f}", f"{fs.duty_a:.3f}", f"{fs.duty_b:.3f}",
                fs.mode.name, int(fs.faults), f"{currents[i, 0]:.4f}"]  # fmt: skip
    return row


_FINGER_FORMAT = ",%.5f,%.5f,%.3f,%.3f,%s,%d,%.4f"


def sample_line(t: float, phase: str, sample: Any, state: Any, currents: np.ndarray) -> str:
    """:func:`sample_row` as the CSV writer writes it, formatted at once (every sample is
    written; a test compares the two)."""
    p = sample.position_m
    head = f"{t:.6f},{phase},{p[0]:.7f},{p[1]:.7f},{p[2]:.7f},{int(sample.visible)},{sample.frame}"
    n = len(currents)
    if state is None:
        return head + ",nan" * (len(FINGER_FIELDS) * n) + "\n"
    values: list[object] = []
    for i, fs in enumerate(state.fingers[:n]):
        values += [fs.theta2, fs.target, fs.duty_a, fs.duty_b, fs.mode.name, int(fs.faults),
                   currents[i, 0]]  # fmt: skip
    return head + (_FINGER_FORMAT * n) % tuple(values) + "\n"


@dataclass(frozen=True)
class GraspHoldConfig:
    pose: str = "grasp-bottle"
    duration_s: float = 600.0
    hits: int = 20  # emulated: hammer hits spread over the hold
    hit_impulse_n_s: float = 0.3  # emulated: each hit's impulse, newton-seconds (N·s)
    hit_duration_s: float = 5e-3
    contact_fraction: float = 0.6  # emulated: the object stops closing fingers there
    tracked_finger: int = 1
    sample_hz: float = 50.0
    baseline_s: float = 1.0
    detect_rad: float = 0.02  # a disturbance: a finger this far off its baseline
    recovery_rad: float = 0.012  # recovered: back within this (about 1.5 ADC counts)
    emulated: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.duration_s) and self.duration_s >= 2 * self.baseline_s):
            raise RunError(
                f"duration_s must be at least twice baseline_s ({2 * self.baseline_s:g} s), "
                f"got {self.duration_s}"
            )
        if not 0 <= self.hits <= 10_000:
            raise RunError(f"hits must be 0..10000, got {self.hits}")
        if self.hits and self.duration_s < 2 * self.baseline_s + 1.0:
            raise RunError(
                f"hits need a hold of at least {2 * self.baseline_s + 1.0:g} s (two baselines "
                f"and time to recover), got {self.duration_s:g} s"
            )
        if not (math.isfinite(self.hit_impulse_n_s) and 0 <= self.hit_impulse_n_s <= 5):
            raise RunError(f"hit_impulse_n_s must lie in [0, 5] N s, got {self.hit_impulse_n_s}")
        if not 0.1 <= self.contact_fraction <= 1.0:
            raise RunError(f"contact_fraction must lie in [0.1, 1], got {self.contact_fraction}")
        if not 0 <= self.tracked_finger <= 4:
            raise RunError(f"tracked_finger must be 0..4, got {self.tracked_finger}")
        if not 5 <= self.sample_hz <= 500:
            raise RunError(f"sample_hz must lie in [5, 500], got {self.sample_hz}")
        if not 0 < self.recovery_rad < self.detect_rad:
            raise RunError("recovery_rad must be > 0 and below detect_rad")

    def hit_plan(
        self, closing: list[int], opening: dict[int, np.ndarray]
    ) -> list[tuple[float, int, tuple[float, float]]]:
        """Seeded hits: (time into the hold, finger, impulse) spread over the hold between its
        baseline and its end window, each within ±45° of the direction that opens its
        finger (``opening``: unit vectors, finger frame)."""
        if not self.hits or not closing:
            return []
        rng = np.random.default_rng(self.seed + 104729)
        lo, hi = self.baseline_s + 0.1, self.duration_s - self.baseline_s - 0.5
        edges = np.linspace(lo, hi, self.hits + 1)
        slots = edges[:-1] + np.diff(edges) * rng.uniform(0.1, 0.6, self.hits)
        out = []
        for t in slots:
            f = int(rng.choice(closing))
            u = opening[f]
            a = math.atan2(u[1], u[0]) + rng.uniform(-math.pi / 4, math.pi / 4)
            j = self.hit_impulse_n_s
            out.append((float(t), f, (j * math.cos(a), j * math.sin(a))))
        return out

    def to_json(self) -> dict[str, Any]:
        return asdict(self)
