"""Tracker frames (issue 9 §6): a sample keeps the tracker's frame number, a frame read twice
is not two samples, and asking for more samples a second than the tracker measures warns."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from utrf.cli.hil import _warn_rate
from utrf.hil.static_loading import config as sl
from utrf.hil.static_loading import run
from utrf.hil.tracker import NewFrames, Registration, SimulatedTracker


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_simulated_tracker_at_its_rate_repeats_frames() -> None:
    clock = Clock()
    tracker = SimulatedTracker(
        lambda: np.array([0.1, 0.02]), clock, frame=Registration.identity(), rate_hz=40.0
    )
    samples = []
    for k in range(100):  # 1 s read at 100 Hz
        clock.t = k * 0.01
        samples.append(tracker.read())
    frames = [s.frame for s in samples]
    assert frames[0] == 0 and frames[-1] == 39
    assert len(set(frames)) == 40  # 40 frames measured, not 100
    pairs = [(a, b) for a, b in itertools.pairwise(samples) if a.frame == b.frame]
    assert pairs and all(np.array_equal(a.position_m, b.position_m) for a, b in pairs)
    new = NewFrames()
    taken = [s for s in samples if new.new(s)]
    assert [s.frame for s in taken] == list(range(40)) and new.repeated == 60


def test_without_a_rate_every_read_is_a_new_frame() -> None:
    tracker = SimulatedTracker(lambda: np.zeros(2), lambda: 0.0, frame=Registration.identity())
    assert [tracker.read().frame for _ in range(5)] == [0, 1, 2, 3, 4]


def test_static_loading_records_new_frames_only() -> None:
    """_record keeps reading until it has n samples of distinct frames."""
    clock = Clock()
    tracker = SimulatedTracker(lambda: np.zeros(2), clock, frame=Registration.identity(),
                               rate_hz=40.0)  # fmt: skip

    def sleep(dt: float) -> None:
        clock.t += dt

    hand = SimpleNamespace(latest=None, faults_seen=[])
    rig = SimpleNamespace(sleep=sleep, hand=hand)
    config = sl.StaticLoadingConfig(tracker_hz=100.0)
    new = NewFrames()

    def write() -> dict[str, int] | None:
        s = tracker.read()
        return {"frame": s.frame} if new.new(s) else None

    rows = run._record(rig, config, 10, write, 0, "test")  # type: ignore[arg-type]
    frames = [r["frame"] for r in rows]
    assert len(frames) == 10 and len(set(frames)) == 10
    assert new.repeated > 0  # it did read repeats, and did not count them


def test_a_sample_rate_above_the_trackers_warns(capsys: pytest.CaptureFixture[str]) -> None:
    _warn_rate(SimpleNamespace(rate_hz=40.0), 100.0, "--tracker-hz")
    assert "--tracker-hz 100 is above the tracker's 40 frames/s" in capsys.readouterr().err
    _warn_rate(SimpleNamespace(rate_hz=40.0), 40.0, "--tracker-hz")
    _warn_rate(SimpleNamespace(rate_hz=None), 400.0, "--tracker-hz")
    assert capsys.readouterr().err == ""
