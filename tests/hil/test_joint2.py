"""The Joint-2 reading's statistics for the rig runs (utrf.hil.joint2), on synthetic
readings of a rounding 10-bit quantiser."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from utrf.hil import joint2
from utrf.hil.joint2 import COUNT_RAD, Joint2Frames
from utrf.models import calibration, kinematics
from utrf.models.geometry import HandGeometry

GEOM = HandGeometry.default().fingers[1].geometry


def _mean_reading_bias(noise: float, positions: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Mean of n noisy rounded readings less the input (counts), at each position."""
    rng = np.random.default_rng(seed)
    return np.array([np.round(x + rng.normal(0.0, noise, n)).mean() - x for x in positions])


def test_the_dither_bound_holds_and_is_tight() -> None:
    assert joint2.dither_bias_bound(0.0) == 0.5
    assert joint2.dither_bias_bound(math.nan) == 0.5
    bounds = [joint2.dither_bias_bound(s) for s in (0.1, 0.2, 0.3, 0.43)]
    assert bounds == sorted(bounds, reverse=True)
    assert bounds[-1] < 0.01  # the emulated encoder's noise: dithered
    positions = np.linspace(0.0, 1.0, 41)
    for noise in (0.2, 0.3):
        bias = _mean_reading_bias(noise, positions, 200_000, seed=1)  # MC error ~1e-3 count
        bound = joint2.dither_bias_bound(noise)
        assert np.abs(bias).max() <= bound + 3e-3
        assert np.abs(bias).max() > 0.8 * bound


def test_the_encoder_noise_comes_from_the_frames_between_samples() -> None:
    rng = np.random.default_rng(2)
    for noise in (0.3, 0.41, 0.6):
        x = rng.uniform(500.0, 520.0, 400)  # a sample's angle (counts), still over 12 frames
        frames = np.round(x[:, None] + rng.normal(0.0, noise, (400, 12))) * COUNT_RAD
        est = joint2.encoder_noise_counts(np.full(400, 12), frames.std(axis=1))
        assert est == pytest.approx(noise, abs=0.03)
    # a quiet encoder: the same code every frame of a sample
    assert joint2.encoder_noise_counts(np.full(400, 12), np.zeros(400)) == 0.0
    assert math.isnan(joint2.encoder_noise_counts(np.ones(5), np.zeros(5)))  # one frame each


def test_step_covariances_see_through_the_finger_moving() -> None:
    """The finger wanders a count (the tip by 2.5 mm) while the tracker (0.1 mm) and the
    reading (0.5 count a sample) err: the paired samples' covariance is the two errors
    only, and a step's is that over its sample count."""
    rng = np.random.default_rng(3)
    loads = np.array([0.0, 1.0, 3.0])
    jac = joint2.tip_jacobian(GEOM, np.zeros(3), loads)
    tips, thetas = [], []
    for j, n in zip(jac, (200, 300, 400), strict=True):
        truth = np.cumsum(rng.normal(0.0, 0.05 * COUNT_RAD, n))  # the hold's wander
        tips.append(np.outer(truth, j) + rng.normal(0.0, 1e-4, (n, 2)))
        thetas.append(truth + rng.normal(0.0, 0.5 * COUNT_RAD, n))
    cov, pooled = joint2.step_covariances(tips, thetas, jac)
    jj = sum((n - 1) * np.outer(j, j) for j, n in zip(jac, (200, 300, 400), strict=True)) / 897
    expected = 1e-8 * np.eye(2) + (0.5 * COUNT_RAD) ** 2 * jj
    np.testing.assert_allclose(pooled, expected, rtol=0.1, atol=2e-9)
    np.testing.assert_allclose(cov[2], pooled / 400)
    with pytest.raises(calibration.CalibrationError, match="two samples"):
        joint2.step_covariances([tips[0][:1]], [thetas[0][:1]], jac[:1])


def test_the_jacobian_is_the_held_tips_slope() -> None:
    th, loads = np.array([0.0, 0.3]), np.array([2.0, 0.0])
    jac = joint2.tip_jacobian(GEOM, th, loads)
    # about R2 * (L-weighted) per rad at the straight finger: the tip rises ~0.31 mm a mrad
    assert jac[0, 1] == pytest.approx(0.33, rel=0.1)
    # the tendons' stretch hardly changes the slope: the rigid finger's R2 d tip / dq
    rigid = GEOM.guide_radii_m[1] * kinematics.jacobian(GEOM, kinematics.q_from_theta2(GEOM, th))
    np.testing.assert_allclose(jac, rigid, atol=0.01)
    h = 1e-3
    hi = calibration.hold_q(GEOM, th + h, loads)
    lo = calibration.hold_q(GEOM, th - h, loads)
    from utrf.models import statics

    slope = (
        statics.solve_batch(GEOM, hi, payload_kg=loads).tip
        - statics.solve_batch(GEOM, lo, payload_kg=loads).tip
    ) / (2 * h)
    np.testing.assert_allclose(jac, slope, rtol=1e-3)


class _FakeHand:
    def __init__(self) -> None:
        self.callbacks: list = []

    def on_state(self, cb):
        self.callbacks.append(cb)
        return lambda: self.callbacks.remove(cb)

    def frame(self, theta2: float) -> None:
        st = SimpleNamespace(fingers=[SimpleNamespace(theta2=0.0), SimpleNamespace(theta2=theta2)])
        for cb in list(self.callbacks):
            cb(st)


def test_frames_are_averaged_between_takes() -> None:
    hand = _FakeHand()
    frames = Joint2Frames(hand, 1)
    assert frames.take()[1] == 0 and math.isnan(frames.take()[0])
    for v in (0.01, 0.02, 0.03):
        hand.frame(v)
    mean, n, sd = frames.take()
    assert (mean, n) == (pytest.approx(0.02), 3) and sd == pytest.approx(np.std([1, 2, 3]) / 100)
    hand.frame(0.5)
    assert frames.take()[:2] == (0.5, 1)  # only the frames since the last take
    frames.close()
    assert hand.callbacks == []
