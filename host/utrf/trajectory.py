"""Minimum-jerk trajectories between joint configurations.

The minimum-jerk profile s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ (Flash and Hogan, 1985) starts and ends
with zero velocity and acceleration, so a tendon-driven finger is not jerked at the ends.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numpy.typing import ArrayLike


def min_jerk_profile(tau: ArrayLike) -> np.ndarray:
    """Normalised position s(τ) for τ in [0, 1] (clamped outside)."""
    t = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    return t**3 * (10.0 + t * (-15.0 + 6.0 * t))


def min_jerk(start: ArrayLike, end: ArrayLike, duration: float, t: ArrayLike) -> np.ndarray:
    """Positions at times t (s) on the minimum-jerk path from start to end over duration.

    Broadcasts: ``t`` of shape (n,) with ``start``/``end`` of shape (k,) gives (n, k).
    """
    if not duration > 0:
        raise ValueError(f"duration must be > 0 s, got {duration!r}")
    a = np.asarray(start, dtype=float)
    b = np.asarray(end, dtype=float)
    s = min_jerk_profile(np.asarray(t, dtype=float) / duration)
    return a + (b - a) * s[..., None] if a.ndim else a + (b - a) * s


def min_jerk_peak_speed(start: ArrayLike, end: ArrayLike, duration: float) -> np.ndarray:
    """Largest speed along the path: 1.875 |end − start| / duration, at mid-time."""
    return 1.875 * np.abs(np.asarray(end, float) - np.asarray(start, float)) / duration


def sample_min_jerk(
    start: ArrayLike, end: ArrayLike, duration: float, rate_hz: float
) -> Iterator[tuple[float, np.ndarray]]:
    """(time, positions) at rate_hz from t = 1/rate to t = duration; the last sample is end."""
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
    n = max(1, int(np.ceil(duration * rate_hz)))
    for k in range(1, n + 1):
        t = min(k / rate_hz, duration)
        yield t, min_jerk(start, end, duration, t)
