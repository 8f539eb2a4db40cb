"""The Joint-2 angle as a rig run measures it, and how well.

The firmware reads each finger's AS5600 (analog, 10-90 % of 5 V a turn) with the MEGA's
10-bit ADC: one count is ``COUNT_RAD`` = 2π / (0.8 · 1024) = 7.67 mrad of Joint-2 angle,
about 2.4 mm at the straight finger's tip, as much as the deflections a static loading run
fits. A step's angle is therefore the mean of many readings, and what that mean is worth
depends on the encoder's noise (``hil/README.md`` has the measurements):

- **Dithered** (noise of about 0.3 count RMS or more; the emulated encoder's 2 mV is 0.41):
  each reading's error (quantisation plus noise) is nearly independent of the angle and of
  the next reading's, so the mean of N readings is good to about 0.5 count / sqrt(N). The
  leftover bias of a dithered quantiser is at most :func:`dither_bias_bound` (0.008 count at
  0.43 count of noise).
- **Not dithered** (a quiet encoder): the readings barely move, and the finger's hold, closed
  on the reading with integral action, parks a loaded finger at one edge of a count (measured:
  without encoder noise the loaded steps' true angle sat 3.6-3.8 mrad above the reading, the
  unloaded ones' 1.9, and the fitted modulus came out 8 % low). Averaging does not help; only
  the bound of half a count does.

:class:`Joint2Frames` collects every telemetry frame's reading so a tracker sample gets the
mean of all of them, not the last one; :func:`step_covariances` turns the paired samples into
each step's tip covariance for the calibration (the tracker's noise and the readings'
random error through the tip's Jacobian), and :func:`encoder_noise_counts` estimates the
noise that decides which case a run is in.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

from utrf.models import calibration, statics
from utrf.models.geometry import FingerGeometry

#: Joint-2 angle of one ADC count: the AS5600's 10-90 % band over a turn on 10 bits (rad)
COUNT_RAD = 2 * math.pi / (0.8 * 1024)
#: encoder noise (counts RMS) below which the readings count as not dithered in the report
DITHER_MIN_COUNTS = 0.3


class Joint2Frames:
    """One finger's measured Joint-2 angle from every telemetry frame, averaged between two
    takes. The board streams its state at up to 500 Hz, a tracker samples at tens of Hz: a
    tracker sample is paired with the mean of the frames since the previous one. On a real
    link the frames arrive on the link's reader thread."""

    def __init__(self, hand: Any, finger: int) -> None:
        self._finger = finger
        self._values: list[float] = []
        self._lock = threading.Lock()
        self._unsubscribe = hand.on_state(self._on_state)

    def _on_state(self, state: Any) -> None:
        value = state.fingers[self._finger].theta2
        with self._lock:
            self._values.append(value)

    def take(self) -> tuple[float, int, float]:
        """(mean, frames, SD of the frames) since the last take; (NaN, 0, NaN) if none came."""
        with self._lock:
            values, self._values = self._values, []
        if not values:
            return math.nan, 0, math.nan
        a = np.asarray(values, dtype=float)
        return float(a.mean()), int(a.size), float(a.std())

    def close(self) -> None:
        self._unsubscribe()


def dither_bias_bound(noise_counts: float) -> float:
    """The largest bias (counts) of the mean reading of a rounding quantiser under Gaussian
    noise of ``noise_counts`` RMS, over where the input sits within a count.

    The quantiser's error is a sawtooth, −Σ sin(2π k x) / (π k); the noise averages harmonic k
    by exp(−2 π² k² σ²). The sum bounds the error, and half a count bounds it anyway (no
    noise)."""
    if not noise_counts > 0:
        return 0.5
    k = np.arange(1, 64)
    terms = np.exp(-2 * math.pi**2 * k**2 * noise_counts**2) / (math.pi * k)
    return float(min(0.5, terms.sum()))


def encoder_noise_counts(frames: np.ndarray, frames_sd_rad: np.ndarray) -> float:
    """The encoder's noise (counts RMS) from the spread of the frames within each tracker
    sample's interval (25 ms at 40 Hz: too short for the finger to move a count): a dithered
    reading's variance is the noise's plus the quantisation's 1/12 count² (Sheppard), which is
    taken out. Readings that hardly change give 0."""
    m = np.asarray(frames, dtype=float)
    sd = np.asarray(frames_sd_rad, dtype=float)
    ok = (m > 1) & np.isfinite(sd)
    if not ok.any():
        return math.nan
    var = (m[ok] * sd[ok] ** 2).sum() / (m[ok] - 1).sum() / COUNT_RAD**2
    return math.sqrt(max(var - 1 / 12, 0.0))


def tip_jacobian(
    geometry: FingerGeometry, theta2_rad: np.ndarray, load_kg: np.ndarray, h: float = 1e-4
) -> np.ndarray:
    """d tip / d θ2 (m/rad), (n, 2): how the held finger's predicted tip moves with the
    Joint-2 angle it is held at (central differences of the Joint-2-held statics)."""
    th = np.asarray(theta2_rad, dtype=float)
    loads = np.asarray(load_kg, dtype=float)
    both_th = np.concatenate([th + h, th - h])
    both_loads = np.concatenate([loads, loads])
    q = calibration.hold_q(geometry, both_th, both_loads)
    tip = statics.solve_batch(geometry, q, payload_kg=both_loads).tip
    return (tip[: th.size] - tip[th.size :]) / (2 * h)


def step_covariances(
    sample_tips_m: Sequence[np.ndarray],
    sample_theta2_rad: Sequence[np.ndarray],
    jacobians: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Each step's tip covariance (m²), (n, 2, 2), for the calibration; and the pooled
    covariance of one paired sample (2, 2).

    A step's residual is its mean tip less the model's tip at its mean Joint-2 reading. Per
    sample, ``tip − J θ2`` cancels what the finger really does (the hold wanders by about a
    count over a second; the tip and the reading move together) and leaves the tracker's
    noise and the reading's error through J. Their covariance, pooled over the steps (the
    same sensors throughout), divided by each step's sample count, is the covariance of that
    step's residual, if the readings' errors are independent: they are when dithered; when
    not, :func:`dither_bias_bound` says what is left."""
    pooled = np.zeros((2, 2))
    dof = 0
    counts = []
    for tips, th, jac in zip(sample_tips_m, sample_theta2_rad, jacobians, strict=True):
        n = len(th)
        counts.append(n)
        if n < 2:
            continue
        d = np.asarray(tips) - np.outer(th, jac)
        pooled += np.cov(d.T, ddof=1) * (n - 1)
        dof += n - 1
    if dof == 0:
        raise calibration.CalibrationError("no step has two samples: no tip covariance")
    pooled /= dof
    return np.array([pooled / max(n, 1) for n in counts]), pooled
