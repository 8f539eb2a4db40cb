import itertools

import numpy as np
import pytest

from utrf.trajectory import min_jerk, min_jerk_peak_speed, sample_min_jerk


def test_endpoints_and_rest_at_both_ends() -> None:
    a, b, T = np.array([0.0, 1.0]), np.array([1.0, -1.0]), 0.8
    assert np.allclose(min_jerk(a, b, T, 0.0), a)
    assert np.allclose(min_jerk(a, b, T, T), b)
    h = 1e-4
    for t in (h, T - h):
        v = (min_jerk(a, b, T, t + h) - min_jerk(a, b, T, t - h)) / (2 * h)
        x0, x1, x2 = (min_jerk(a, b, T, s) for s in (t - h, t, t + h))
        acc = (x2 - 2 * x1 + x0) / h**2
        assert np.abs(v).max() < 1e-5  # vs a peak of 4.7; a cubic profile gives 2e-3 here
        assert np.abs(acc).max() < 0.1  # 60 t |b-a| / T^3 near the ends; a cubic has 18.75


def test_monotonic_and_peak_speed_matches_the_closed_form() -> None:
    t = np.linspace(0.0, 2.0, 20001)
    x = min_jerk(0.0, 3.0, 2.0, t)
    v = np.gradient(x, t)
    assert np.all(np.diff(x) >= 0)
    assert v.max() == pytest.approx(float(min_jerk_peak_speed(0.0, 3.0, 2.0)), rel=1e-4)
    assert t[np.argmax(v)] == pytest.approx(1.0, abs=1e-3)


def test_broadcasts_times_over_joints() -> None:
    out = min_jerk([0.0, 0.0, 0.0], [1.0, 2.0, 3.0], 1.0, np.linspace(0, 1, 5))
    assert out.shape == (5, 3)
    assert np.allclose(out[:, 1], 2 * out[:, 0])


def test_sampling_ends_exactly_on_the_goal() -> None:
    samples = list(sample_min_jerk([0.0], [1.0], 0.25, 50.0))
    assert len(samples) == 13  # ceil(0.25 * 50) = 13: the last is at t = duration
    assert samples[-1][0] == pytest.approx(0.25)
    assert samples[-1][1][0] == pytest.approx(1.0)
    times = [t for t, _ in samples]
    assert all(b > a for a, b in itertools.pairwise(times))


@pytest.mark.parametrize("duration", [0.0, -1.0, float("nan")])
def test_bad_duration_is_refused(duration: float) -> None:
    with pytest.raises(ValueError, match="duration"):
        min_jerk(0.0, 1.0, duration, 0.5)
