"""The plant's numbers and the findings drawn from them, without a board: the lag fitted from
a step from rest read through a 10-bit encoder, and the thresholds that tell a weak motor and
slack from the ±30 % spread every build's motors have."""

from __future__ import annotations

import math

import numpy as np
import pytest

from utrf.bringup.identify import LAG_DUTY, Plant, _fit_from_rest
from utrf.bringup.plant_check import (
    MORE_LAGS,
    MORE_REVERSALS,
    SLACK_RAD,
    lags_read,
    near,
    plant_findings,
    slack_rad,
)
from utrf.bringup.pulses import Trace

REF = Plant(K=2.63, tau=0.010, u_f=0.03, backlash_rad=0.0, steps=0)
COUNT = 2 * math.pi / 1024  # one count of the AS5600 as the board reads it


def _step(tau: float, v: float, seed: int, delay_s: float = 0.01) -> Trace:
    """A step from rest at 1 kHz: duty applied ``delay_s`` after the trace starts, the angle
    a first-order speed response, noise and the encoder's counts on it."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 0.26, 0.001)
    s = np.clip(t - delay_s, 0.0, None)
    th = v * (s - tau * (1 - np.exp(-s / tau))) + rng.normal(0, 0.002, len(t))
    th = np.round(th / COUNT) * COUNT
    duty = np.where(t >= delay_s, 0.1 + LAG_DUTY, 0.1)
    theta2 = np.zeros((len(t), 5))
    theta2[:, 1] = th
    da, db = np.zeros((len(t), 5)), np.zeros((len(t), 5))
    da[:, 1], db[:, 1] = duty, 0.1
    return Trace(1, LAG_DUTY, t, theta2, da, db, "time")


@pytest.mark.parametrize("tau", [0.008, 0.010, 0.033])
def test_the_lag_is_resolved_below_one_count(tau: float) -> None:
    fits = [_fit_from_rest(_step(tau, 0.75, seed), 1) for seed in range(5)]
    got = np.median([f[1] for f in fits if f is not None])
    assert got == pytest.approx(tau, rel=0.3)


def _plant(K: float, flex: float, ext: float, u_f: float = 0.03) -> Plant:
    return Plant(K, min(flex, ext), u_f, 0.0, 8, {}, {"flex": flex, "extend": ext})


@pytest.mark.parametrize("force", [0.7, 1.0, 1.3])
@pytest.mark.parametrize("speed", [0.7, 1.0, 1.3])
def test_the_spread_of_builds_is_not_a_finding(force: float, speed: float) -> None:
    """τ = m v0 / F, K ∝ v0: a build within ±30 % of the model's motors names nothing."""
    K, tau = REF.K * speed, REF.tau * speed / force
    assert plant_findings("index", _plant(K, 1.3 * tau, 0.6 * tau), REF) == []


def test_a_weak_motor_is_named_and_fixable() -> None:
    got = plant_findings("index", _plant(1.94, 0.0252, 0.0679), REF)  # measured, weak-motor 0.3
    assert [f.kind for f in got] == ["weak-motor"] and got[0].fixable
    # u_f = 2 F_coulomb / F_stall: the same friction takes more duty on a weaker motor
    assert [f.kind for f in plant_findings("i", _plant(1.94, 0.0252, 0.0679, 0.1), REF)] == [
        "weak-motor"
    ]
    # the slowest random build measured (late both ways, 2.8x and 2.1x) is not weak
    assert plant_findings("i", _plant(2.88, 0.0308, 0.0232), REF) == []


def test_slack_is_named_not_weakness_nor_friction() -> None:
    # the lag fits at their bound (measured, slack 1.5 mm), the take-up 0.11 s: 0.074 rad
    p = _plant(2.30, 0.001, 0.001, 0.014)
    got = plant_findings("index", p, REF, slack_rad(p, REF, 0.11))
    assert [f.kind for f in got] == ["slack"] and not got[0].fixable
    # Joint 2 loose between its strands also makes the steps' friction look high
    p = _plant(2.30, 0.001, 0.001, 0.1)
    assert [f.kind for f in plant_findings("i", p, REF, 0.08)] == ["slack"]
    # measured, seed 30's fault-free little finger: one take-up of 0.077 s read 0.038 rad
    fine = _plant(2.253, 0.0122, 0.0150, 0.0216)
    assert plant_findings("little", fine, REF, slack_rad(fine, REF, 0.077)) == []


def test_slack_late_one_way_only_is_named() -> None:
    """Joint 2 leaning on one strand under gravity follows that way at the strand's lag and
    waits for the other strand the other way, and its speed is uneven over the travel
    (measured, slack 1.5 mm on the index: 0.019 s flexing, 0.130 s extending, 1.44 uneven);
    evenly too, the lags being medians of three steps each way (one step's scattered: seed
    43's weak ring read 1.1 and 11.9 from one each)."""
    p = _plant(2.64, 0.0188, 0.130)
    got = plant_findings("index", p, REF, uneven=True)
    assert [f.kind for f in got] == ["slack"] and not got[0].fixable
    assert [f.kind for f in plant_findings("i", p, REF)] == ["slack"]
    # late both ways, one 3 times the other (7.5 times the model's lag): weak, not slack
    assert [f.kind for f in plant_findings("i", _plant(2.64, 0.025, 0.075), REF)] == ["weak-motor"]


def test_friction_late_one_way_is_not_weakness() -> None:
    """A weak motor is late both ways; heavy friction may be late one way (measured, campaign
    seed 47's middle finger, friction 10 N: 8.8 and 2.1 times the model's lag, u_f 0.145,
    which a motor that late would explain)."""
    got = plant_findings("i", _plant(1.76, 0.0585, 0.0142, 0.145), REF)
    assert [f.kind for f in got] == ["friction"]


@pytest.mark.parametrize(
    ("plant", "take_up"),
    [
        (_plant(2.54, 0.0123, 0.0178, 0.025), 0.038),  # the model build
        (_plant(1.94, 0.0252, 0.0679, 0.047), 0.043),  # weak-motor 0.3
        (_plant(2.88, 0.0308, 0.0232, 0.034), 0.050),  # random build, seed 2
    ],
)
def test_a_late_motor_is_not_slack(plant: Plant, take_up: float) -> None:
    """Slack is a travel beyond the motor's own lag: a motor slow to come up to speed (its
    lag measured, not the model's) leaves the open stop as late without any slack."""
    assert slack_rad(plant, REF, take_up) < SLACK_RAD
    assert slack_rad(_plant(plant.K, 0.001, 0.001, plant.u_f), REF, take_up) > slack_rad(
        plant, REF, take_up
    )


def test_friction_and_a_slow_motor_are_named() -> None:
    assert [f.kind for f in plant_findings("i", _plant(2.6, 0.01, 0.008, 0.19), REF)] == [
        "friction"
    ]
    assert [f.kind for f in plant_findings("i", _plant(1.1, 0.004, 0.004), REF)] == ["slow-motor"]


def test_a_low_speed_gain_from_steps_friction_barely_lets_move_is_not_a_slow_motor() -> None:
    """Measured, campaign seed 5's little finger (10 N of friction): the 0.15 step did not
    move it, and the line through 0.3 and 0.4 read K 1.03 (0.39 of the model's) and u_f
    0.086 once (K 0.75-0.78, u_f 0.24 in six other runs). A slow motor with the model's force
    moves at 0.15, only slowly (every slow-motor reading of this issue's runs)."""
    stiff = _plant(1.032, 0.0055, 0.0055, 0.086)
    stiff.first_duty = 0.3
    assert [f.kind for f in plant_findings("little", stiff, REF)] == ["friction"]
    moved = _plant(1.032, 0.0055, 0.0055, 0.086)
    moved.first_duty = 0.15
    assert [f.kind for f in plant_findings("little", moved, REF)] == ["slow-motor", "friction"]


def test_the_steps_from_rest_are_taken_only_where_a_rule_reads_them() -> None:
    assert lags_read(_plant(2.3, 0.02, 0.02), REF)
    assert not lags_read(_plant(1.06, 0.048, 0.001), REF)  # a slow motor: its lag unresolved
    assert not lags_read(_plant(2.2, 0.05, 0.05, 0.26), REF)  # a crawl: not timed


def test_a_slow_motors_unresolved_lag_is_not_weakness() -> None:
    """At a slow motor's speed the lag is far under a count: the fits scatter (measured,
    slow-motor 0.45: 0.048 s closing, at the fit's bound opening); only its speed is named."""
    got = plant_findings("i", _plant(1.06, 0.048, 0.001), REF)
    assert [f.kind for f in got] == ["slow-motor"]


def test_friction_beyond_what_a_late_motor_explains_is_friction() -> None:
    """Heavy friction also makes the steps from rest late (measured, friction 11 N: 6.5 and
    3.0 times the model's lag, u_f 0.25); a weak motor's friction duty grows only as its lag."""
    got = plant_findings("i", _plant(2.6, 0.065, 0.030, 0.249), REF)
    assert [f.kind for f in got] == ["friction"] and got[0].fixable
    assert [f.kind for f in plant_findings("i", _plant(2.6, 0.065, 0.030, 0.1), REF)] == [
        "weak-motor"
    ]


@pytest.mark.parametrize(
    ("flex", "ext", "slack"),
    # measured lag ratios of slack fingers of campaign seeds 4, 1 and 7 (the travel before
    # Joint 2 left the open stop under the threshold on each)
    [(0.09, 27.3, True), (0.13, 8.31, True), (0.11, 19.4, True),
     # and of fingers without slack: spread builds, a weak motor, friction
     (2.69, 0.14, False), (0.14, 2.27, False), (0.38, 3.97, False), (3.42, 9.21, False),
     (6.5, 3.0, False)],
)  # fmt: skip
def test_slack_shows_as_a_lag_one_way_only(flex: float, ext: float, slack: bool) -> None:
    tau = REF.tau  # K as the model's: the ratios are the lags over the model's
    p = _plant(REF.K, flex * tau, ext * tau, 0.03 if ext < 5 else 0.05)
    kinds = [f.kind for f in plant_findings("i", p, REF, 0.01)]
    assert ("slack" in kinds) is slack, kinds


def test_a_late_finger_slow_to_reverse_is_slack() -> None:
    """Late both ways as a weak motor is, but each reversal waits longer still beyond its lag:
    Joint 2 waits for a slack strand (measured, campaign seed 47's slack thumb: 2.7 and 6.1
    times the model's lag, reversal 0.105 s; seed 29's weak thumb 0.078 s, lag 0.027)."""
    slack = _plant(2.25, 0.0230, 0.0522)
    slack.reversal_s = {"0.3": 0.105}
    got = plant_findings("thumb", slack, REF)
    assert [f.kind for f in got] == ["slack"] and not got[0].fixable
    weak = _plant(1.92, 0.0294, 0.0265, 0.068)
    weak.reversal_s = {"0.3": 0.078}
    assert [f.kind for f in plant_findings("thumb", weak, REF)] == ["weak-motor"]


def test_heavy_friction_late_one_way_or_slow_to_reverse_is_not_slack() -> None:
    """Breakaway friction delays a start, one way more under gravity, and a reversal; it
    takes the duty to move that slack does not (heavy friction at least 0.093 over the
    model's, slack fingers at most 0.037: docs/bringup.md)."""
    late_one_way = _plant(REF.K, 9.0 * REF.tau, 0.3 * REF.tau, 0.2)
    assert [f.kind for f in plant_findings("thumb", late_one_way, REF)] == ["friction"]
    slow_reversal = _plant(REF.K, REF.tau, REF.tau, 0.2)
    slow_reversal.reversal_s = {"0.3": 0.1}
    assert [f.kind for f in plant_findings("thumb", slow_reversal, REF)] == ["friction"]
    slow_reversal.u_f = 0.05  # the same readings at a free finger's duty: slack
    assert [f.kind for f in plant_findings("thumb", slow_reversal, REF)] == ["slack"]
    # measured, seed 10's thumb (10 N): its lag steps at 0.3 crawl (two at the fit's bound)
    crawl = _plant(2.206, 0.3, 0.0445, 0.262)
    assert [f.kind for f in plant_findings("thumb", crawl, REF)] == ["friction"]


def test_a_reading_near_its_threshold_is_read_again_and_the_median_decides() -> None:
    """Measured (seed 15's fault-free ring, K 1.815): three steps each way, medians 0.033 and
    0.023 s (4.8 and 3.3 times the model's lag at that K: weak-motor); four more each way,
    the medians of all seven 0.016 and 0.013 s (2.3 and 1.9 times): nothing."""
    first = Plant(1.815, math.nan, 0.035, 0.0, 8)
    first.add_fits({"flex": [0.033, 0.034, 0.011], "extend": [0.025, 0.015, 0.023]}, {})
    ref = REF
    assert [f.kind for f in plant_findings("ring", first, ref)] == ["weak-motor"]
    assert near(first, ref) == (MORE_LAGS, 0)
    first.add_fits({"flex": [0.012, 0.016, 0.016], "extend": [0.013, 0.013, 0.013, 0.011]}, {})
    assert first.lag_s == {"flex": 0.016, "extend": 0.013} and first.tau == 0.013
    assert plant_findings("ring", first, ref) == []
    # far from every threshold: nothing more is read
    assert near(_plant(REF.K, 1.3 * REF.tau, 0.6 * REF.tau), REF) == (0, 0)
    # a reversal within 0.02 s under its threshold is timed again
    close = _plant(REF.K, REF.tau, REF.tau)
    close.reversal_s = {"0.3": REF.tau + 0.045}
    assert near(close, REF) == (0, MORE_REVERSALS)
