"""Tracker maths: registration of tracker coordinates to the finger frame, the simulated
tracker, and the optional NDI package's error message."""

from __future__ import annotations

import builtins
import math
import sys

import numpy as np
import pytest

from utrf.hil import tracker as tr
from utrf.hil.tracker import Registration, SimulatedTracker, TrackerError, register
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry

GEOM = HandGeometry.default().fingers[1].geometry


def _poses() -> np.ndarray:
    q = kinematics.q_from_theta2(GEOM, np.array([-0.35, 0.0, 0.35, 0.7]))
    return np.array([kinematics.tip_position(GEOM, x) for x in q])


def test_registration_recovers_a_rigid_frame() -> None:
    rot = tr.rotation_from_euler(1.1, -0.4, 0.3)
    trans = np.array([0.1, -0.2, 0.35])
    pts = _poses()
    seen = pts @ rot[:, :2].T + trans  # (x, y, 0) placed in the tracker frame
    reg = register(pts, seen)
    np.testing.assert_allclose(reg.rotation, rot, atol=1e-12)
    np.testing.assert_allclose(reg.translation_m, trans, atol=1e-12)
    assert reg.rms_residual_m < 1e-12 and reg.points == 4
    # and back: any point of the finger's plane, and what lies off it
    p = np.array([[0.12, 0.05], [0.169, -0.01]])
    np.testing.assert_allclose(reg.to_finger(reg.to_tracker(p)), p, atol=1e-12)
    off = reg.to_tracker(p) + 0.002 * rot[:, 2]
    np.testing.assert_allclose(reg.out_of_plane(off), [0.002, 0.002], atol=1e-12)
    back = Registration.from_json(reg.to_json())
    np.testing.assert_allclose(back.rotation, reg.rotation)


def test_noisy_registration_residual_is_the_noise() -> None:
    rng = np.random.default_rng(4)
    rot = tr.rotation_from_euler(-0.5, 0.2, 0.9)
    q = kinematics.q_from_theta2(GEOM, np.linspace(-0.6, 1.2, 40))
    pts = np.array([kinematics.tip_position(GEOM, x) for x in q])
    seen = pts @ rot[:, :2].T + np.array([0.3, 0.1, -0.1]) + rng.normal(0, 1e-4, (40, 3))
    reg = register(pts, seen)
    # 3 axes of 0.1 mm noise, 6 parameters fitted from 120 numbers
    assert reg.rms_residual_m == pytest.approx(1e-4 * math.sqrt(3 * (120 - 6) / 120), rel=0.25)
    assert np.abs(reg.to_finger(seen) - pts).max() < 5e-4


@pytest.mark.parametrize(
    ("finger", "tracker", "needle"),
    [
        (np.zeros((3, 3)), np.zeros((3, 3)), r"finger points must be \(n, 2\)"),
        (np.zeros((3, 2)), np.zeros((3, 2)), r"tracker points must be \(n, 3\)"),
        (np.zeros((3, 2)), np.zeros((4, 3)), "3 finger points but 4"),
        (np.zeros((2, 2)), np.zeros((2, 3)), "at least 3 poses"),
        (np.array([[0, 0], [1, 1], [2, 2.0]]), np.zeros((3, 3)), "one line"),
        (np.array([[0, 0], [1, 0], [0, 1.0]]), np.full((3, 3), np.nan), "finite"),
    ],
)
def test_bad_registration_points_are_named(finger, tracker, needle: str) -> None:
    with pytest.raises(TrackerError, match=needle):
        register(finger, tracker)


def test_registration_file_must_hold_a_rotation() -> None:
    with pytest.raises(TrackerError, match="rotation"):
        Registration.from_json({"rotation": (2 * np.eye(3)).tolist(), "translation_m": [0, 0, 0]})
    with pytest.raises(TrackerError, match="missing"):
        Registration.from_json({"translation_m": [0, 0, 0]})


def test_simulated_tracker_is_seeded_and_in_its_own_frame() -> None:
    frame = Registration(tr.rotation_from_euler(0.3, 0.1, -0.2), np.array([0.05, 0.2, -0.1]))
    tip = np.array([0.17, 0.001])
    clock = iter(np.arange(100) * 0.025)

    def make(seed: int) -> SimulatedTracker:
        return SimulatedTracker(lambda: tip, lambda: next(clock), frame=frame, noise_m=1e-4,
                                seed=seed)  # fmt: skip

    a, b = make(1), make(1)
    ra = [a.read() for _ in range(20)]
    rb = [b.read() for _ in range(20)]
    assert all(np.array_equal(x.position_m, y.position_m) for x, y in zip(ra, rb, strict=True))
    pos = np.array([s.position_m for s in ra])
    np.testing.assert_allclose(frame.to_finger(pos.mean(axis=0))[0], tip, atol=1e-4)
    assert 3e-5 < pos.std(axis=0).mean() < 3e-4  # noisy, about the 0.1 mm asked for
    assert not np.allclose(pos.mean(axis=0)[:2], tip, atol=1e-2)  # not the finger frame
    lossy = SimulatedTracker(lambda: tip, lambda: 0.0, frame=frame, dropout=0.5, seed=3)
    reads = [lossy.read() for _ in range(200)]
    hidden = [s for s in reads if not s.visible]
    assert 60 < len(hidden) < 140 and all(np.isnan(s.position_m).all() for s in hidden)
    lossy.close()
    with pytest.raises(TrackerError, match="closed"):
        lossy.read()


def test_a_reading_taken_now_and_finished_later_is_the_one_read_gives() -> None:
    frame = Registration(tr.rotation_from_euler(0.3, 0.1, -0.2), np.array([0.05, 0.2, -0.1]))
    tip = np.array([0.17, 0.001])
    now = [0.0]

    def make() -> SimulatedTracker:
        return SimulatedTracker(lambda: tip, lambda: now[0], frame=frame, noise_m=1e-4, seed=4)

    plain, later = make(), make()
    for k in range(5):
        now[0], tip[:] = 0.02 * k, (0.17 + 0.001 * k, 0.001)
        expected = plain.read()
        finish = later.read_later()  # taken now ...
        now[0], tip[:] = 9.0, (0.0, 0.0)  # ... the rig moves on before it is finished
        got = finish()
        assert got.time_s == expected.time_s and got.frame == expected.frame
        assert np.array_equal(got.position_m, expected.position_m)


def test_ndi_tracker_without_its_package_says_how_to_install(monkeypatch) -> None:
    real_import = builtins.__import__

    def no_ndi(name, *args, **kwargs):
        if name.startswith("sksurgerynditracker"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.delitem(sys.modules, "sksurgerynditracker", raising=False)
    monkeypatch.delitem(sys.modules, "sksurgerynditracker.nditracker", raising=False)
    monkeypatch.setattr(builtins, "__import__", no_ndi)
    with pytest.raises(TrackerError) as info:
        tr.NDIAuroraTracker("/dev/ttyUSB0")
    text = str(info.value)
    assert "scikit-surgerynditracker" in text
    assert "pip install 'utrf[rig]'" in text and "pip install -e '.[rig]'" in text


def test_ndi_tracker_reads_through_the_package(monkeypatch) -> None:
    """The adapter's side of the package's API: settings, mm to m, NaN for an unseen tool."""
    made: dict = {}

    class FakeNDI:
        def __init__(self, settings: dict) -> None:
            made["settings"] = settings
            self.frames = [
                np.array([[1, 0, 0, 10.0], [0, 1, 0, -20.0], [0, 0, 1, 300.0], [0, 0, 0, 1]]),
                np.full((4, 4), np.nan),
            ]

        def start_tracking(self) -> None:
            made["started"] = True

        def get_frame(self):
            f = self.frames.pop(0)
            return [1], [0.0], [7], [f], [0.12]

        def stop_tracking(self) -> None:
            made["stopped"] = True

        def close(self) -> None:
            made["closed"] = True

    monkeypatch.setattr(tr, "_import_ndi", lambda: FakeNDI)
    t = tr.NDIAuroraTracker("/dev/ttyUSB3", clock=lambda: 5.0)
    assert made["settings"]["tracker type"] == "aurora"
    assert made["settings"]["serial port"] == "/dev/ttyUSB3"
    s = t.read()
    assert s.visible and s.time_s == 5.0 and s.quality == pytest.approx(0.12)
    assert s.frame == 7  # the Aurora's own frame number is kept
    np.testing.assert_allclose(s.position_m, [0.010, -0.020, 0.300])
    s2 = t.read()
    assert not s2.visible and np.isnan(s2.position_m).all()
    t.close()
    assert made["stopped"] and made["closed"]
