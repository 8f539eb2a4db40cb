import math
from pathlib import Path

import numpy as np
import pytest

from utrf.models.geometry import HandGeometry
from utrf.poses import PoseError, PoseLibrary

HAND = HandGeometry.default()
REQUIRED = ["open", "fist", "point", "rock-and-roll", "shaka", "thumbs-up", "pinch", "ok"]


@pytest.fixture
def library() -> PoseLibrary:
    return PoseLibrary.load(hand=HAND, include_user=False)


def test_builtin_library_has_the_issue_poses_and_grasps(library: PoseLibrary) -> None:
    for name in REQUIRED:
        assert name in library
    grasps = [p for p in library.values() if p.grasp is not None]
    assert len(grasps) >= 3
    assert all(0 < p.grasp.effort <= 1 for p in grasps)


def test_flexion_resolves_through_the_coupling(library: PoseLibrary) -> None:
    # flexion f puts theta1 at f * theta1_max, so theta2 = f * theta1_max * R1 / R2.
    pose = library["shaka"]
    theta2 = pose.theta2(HAND)
    for i, finger in enumerate(HAND.fingers):
        g = finger.geometry
        f = pose.targets[finger.name].value
        expected = f * g.theta1_range_rad[1] * g.guide_radii_m[0] / g.guide_radii_m[1]
        assert theta2[i] == pytest.approx(expected, rel=1e-12)
    assert theta2[0] == 0 and theta2[4] == 0  # thumb and little straight
    assert min(theta2[1:4]) > 1.0  # the others closed


def test_every_builtin_pose_is_within_each_fingers_range(library: PoseLibrary) -> None:
    for pose in library.values():
        q = pose.q(HAND)
        for i, finger in enumerate(HAND.fingers):
            lo, hi = finger.geometry.q_range_m
            assert lo <= q[i] <= hi, (pose.name, finger.name)


def test_override_in_degrees_and_metres(tmp_path: Path) -> None:
    f = tmp_path / "mine.toml"
    f.write_text(
        "[pose.custom]\n"
        "flexion = { index = 0.5 }\n"
        "[pose.custom.override.middle]\ntheta2_deg = 30.0\n"
        "[pose.custom.override.ring]\nq_m = 0.004\n"
    )
    lib = PoseLibrary.load([f], hand=HAND, include_user=False)
    theta2 = lib["custom"].theta2(HAND)
    assert theta2[2] == pytest.approx(math.radians(30.0))
    assert theta2[3] == pytest.approx(0.004 / HAND.fingers[3].geometry.guide_radii_m[1])
    assert theta2[0] == 0.0  # fingers left out stay straight


def test_user_file_replaces_a_builtin_by_name(tmp_path: Path, monkeypatch) -> None:
    f = tmp_path / "poses.toml"
    f.write_text('[pose.fist]\ndescription = "mine"\nflexion = { index = 0.1 }\n')
    monkeypatch.setenv("UTRF_POSES", str(f))
    lib = PoseLibrary.load(hand=HAND)
    assert lib["fist"].description == "mine"
    assert np.count_nonzero(lib["fist"].theta2(HAND)) == 1


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[pose.x]\nflexion = { pinky = 0.5 }\n", ["'x'", "pinky"]),
        ("[pose.x]\nflexion = { index = 1.5 }\n", ["flexion.index", "[-1, 1]"]),
        ("[pose.x]\nflexion = { index = 'a' }\n", ["flexion.index", "number"]),
        ("[pose.x]\ncolour = 'red'\n", ["colour"]),
        ("[pose.x]\n[pose.x.override.index]\ntheta2_deg = 170.0\n", ["index", "outside"]),
        ("[pose.x]\n[pose.x.override.index]\ntheta2_deg = 1.0\nq_m = 0.001\n", ["override.index"]),
        ("[pose.x]\n[pose.x.grasp]\neffort = 0.0\n", ["grasp.effort"]),
        ("[pose.x\n", ["not valid TOML"]),
    ],
)
def test_bad_pose_files_name_what_is_wrong(tmp_path: Path, text: str, words: list[str]) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(PoseError) as err:
        PoseLibrary.load([f], hand=HAND, include_user=False)
    for w in words:
        assert w in str(err.value)
    assert str(f) in str(err.value)


def test_unknown_pose_lists_the_known_ones(library: PoseLibrary) -> None:
    with pytest.raises(KeyError, match="shaka"):
        library["shakka"]
