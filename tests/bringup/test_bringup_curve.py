"""The stop search's legs read as a curve, without a board: a reading that stands still while
driven (Joint 2 waiting on a slack strand) against one that only slows (an off-centre
magnet), the legs of a search read together, and a leg's samples from the old frame left out."""

from __future__ import annotations

import math

import numpy as np

from utrf.bringup.diagnose import dwell_rad, reading_curve
from utrf.bringup.finger import DWELL_RAD, stood
from utrf.bringup.pulses import Trace

COUNT = 2 * math.pi / 1024
F = 1


def _leg(
    theta: np.ndarray, t: np.ndarray, duty: float, stop: str = "stall", off_s: float = 0.0
) -> Trace:
    """``off_s``: the leg's last seconds with the board no longer driving it (DUTY 0)."""
    th = np.zeros((len(t), 5))
    th[:, F] = np.round(theta / COUNT) * COUNT  # the encoder's counts
    da, db = np.full((len(t), 5), 0.1), np.full((len(t), 5), 0.1)  # the pretension
    on = t <= t[-1] - off_s
    (da if duty > 0 else db)[on, F] += abs(duty)
    return Trace(F, duty, t, th, da, db, stop)


def _drive(speed_at: object, start: float, end: float, direction: int = 1) -> Trace:
    """A leg at one duty from ``start`` to ``end`` (rad), its speed ``speed_at(angle)``,
    ended by the stall rule (0.2 s standing at the end)."""
    t, th, now, x = [0.0], [start], 0.0, start
    while direction * (end - x) > 0:
        now += 0.001
        x += direction * 0.001 * speed_at(x)  # type: ignore[operator]
        t.append(now)
        th.append(x)
    for _ in range(200):
        now += 0.001
        t.append(now)
        th.append(end)
    return _leg(np.array(th), np.array(t), 0.35 * direction)


def test_a_pause_is_a_dwell_and_a_slowing_is_not() -> None:
    steady = _drive(lambda x: 1.0, -1.6, 1.6)
    # off-centre by 0.4 rad: the reading's speed 1 - 0.4 cos(angle), never standing
    scaled = _drive(lambda x: 1.0 - 0.4 * math.cos(x), -1.6, 1.6)
    # slack: the reading stands 0.15 s at 0.3 rad while the motor crosses the strand's slack
    state = {"wait": 0.15}

    def pausing(x: float) -> float:
        if x >= 0.3 and state["wait"] > 0:
            state["wait"] -= 0.001
            return 0.0
        return 1.0

    paused = _drive(pausing, -1.6, 1.6)
    assert dwell_rad(steady, 1) < 0.02
    assert dwell_rad(scaled, 1) < 0.02
    assert dwell_rad(paused, 1) > 0.1


def test_the_curve_reads_every_leg_of_a_search() -> None:
    """A search of two legs (the board's limit ends the first mid-travel): the curve compares
    the whole travel, and an off-centre magnet's uneven speed shows over it."""
    speed = lambda x: 1.0 - 0.4 * math.cos(x)  # noqa: E731
    legs = [_drive(speed, -1.6, 0.0), _drive(speed, 0.0, 1.6)]
    opening = _drive(speed, 1.6, -1.0, -1)
    one = reading_curve(legs[1], opening)
    both = reading_curve(legs, opening)
    assert both["covered_rad"] > one["covered_rad"]
    assert both["spread"] > 1.2
    even = reading_curve(
        [_drive(lambda x: 1.0, -1.6, 0.0), _drive(lambda x: 1.0, 0.0, 1.6)],
        _drive(lambda x: 1.0, 1.6, -1.0, -1),
    )
    assert even["spread"] < 1.1


def test_a_leg_is_read_from_its_frame_on() -> None:
    """Samples streamed before a new encoder offset took are in the old frame: ``after``
    leaves them out, so the leg's change is the finger's."""
    t = np.arange(0.0, 0.5, 0.001)
    theta = np.where(t < 0.01, -1.6, 0.5 * np.clip(t - 0.02, 0.0, None))
    leg = _leg(theta, t, 0.35)
    assert abs(leg.delta()[F] - 0.24) > 1.0  # the old frame's first sample
    assert abs(leg.after(0.01).delta()[F] - 0.24) < 0.01


def test_a_stand_after_the_drive_stopped_is_not_a_dwell() -> None:
    """The board ramps a leg's duty down at a limit before the host's stall rule ends it (seed
    19's little finger: 0.07 s standing 0.41 s before the end, named slack): only the samples
    driven at the leg's duty count."""
    t = np.arange(0.0, 2.3, 0.001)
    th = np.minimum(0.8 * t, 0.8 * 1.8)  # at 0.8 rad/s until the limit, then standing
    th[(t > 1.60) & (t < 1.70)] = 0.8 * 1.60  # a stand while the duty ramps down
    th[t >= 1.70] = 0.8 * 1.60 + 0.8 * (np.minimum(t[t >= 1.70], 1.8) - 1.70)
    driven = dwell_rad(_leg(th, t, 0.35), 1)
    assert driven > DWELL_RAD  # read as if driven throughout: a dwell
    assert dwell_rad(_leg(th, t, 0.35, off_s=2.3 - 1.6), 1) < DWELL_RAD


def test_the_stand_at_the_stop_that_ended_a_leg_is_not_a_dwell() -> None:
    """Driven onto the closed stop, the reading stands there until the stall rule ends the
    leg, later than the 0.3 s cut when a count of noise restarts it (seed 60's ring: 0.4 s,
    a count up after 0.3 s, named slack): that stand is not Joint 2 waiting mid-travel."""
    t = np.arange(0.0, 2.45, 0.001)
    th = np.minimum(0.8 * t, 0.8 * 2.05)
    th[t > 2.13] += COUNT  # a count of noise just before the cut: "went on"
    assert dwell_rad(_leg(th, t, 0.35), 1) < 0.02


def test_a_short_stand_on_an_uneven_reading_is_slack() -> None:
    """Measured (docs/bringup.md): seed 46's slack middle finger stood 0.035 rad and ran 1.17
    uneven, seed 38's slack thumb 0.035 and 1.27; fingers with neither slack nor an
    off-centre magnet ran at most 1.07 uneven (seed 19's little finger stood 0.045 in the
    ramp down, at 1.03), off-centre magnets stood at most 0.019 (seed 43's index: 0.016 at
    1.72)."""
    assert stood({"dwell_rad": 0.035, "spread": 1.17})
    assert stood({"dwell_rad": 0.035, "spread": 1.27})
    assert not stood({"dwell_rad": 0.035, "spread": 1.07})
    assert not stood({"dwell_rad": 0.016, "spread": 1.72})
    assert not stood({"dwell_rad": 0.035, "spread": math.nan})  # no curve: the dwell alone
    assert stood({"dwell_rad": 0.045, "spread": math.nan})
