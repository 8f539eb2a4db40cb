"""The MJCF thumb opposes the fingers without striking them: every pose of the pose library,
and every move between two of them, keeps it clear of the other fingers and the palm, and in
pinch and ok its tip meets the index's. (Its earlier placement struck the flexed index in the
fist: the firmware latched STALL and `make demo` failed on the MuJoCo plant.)"""

from __future__ import annotations

import itertools
import math

import mujoco
import numpy as np
import pytest

from utrf.models import mjcf
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary

HAND = HandGeometry.default()
NAMES = [f.name for f in HAND.fingers]
CLEARANCE_M = 0.002  # what the placement was chosen for (docs/mujoco.md, "The thumb")


@pytest.fixture(scope="module")
def hand() -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mjcf.hand_model()
    model.geom_margin[:] = 0.01  # report pairs within 10 mm, with their distance
    return model, mujoco.MjData(model)


def _thumb_clearance(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """The thumb's smallest distance (m) to another finger or the palm (10 mm when farther)."""
    gap = 0.01
    for c in data.contact[: data.ncon]:
        names = (model.geom(c.geom1).name, model.geom(c.geom2).name)
        if any(n.startswith("thumb") for n in names):
            gap = min(gap, float(c.dist))
    return gap


def _library() -> dict[str, dict[str, float]]:
    lib = PoseLibrary.load(hand=HAND, include_user=False)
    return {name: dict(zip(NAMES, lib[name].q(HAND), strict=True)) for name in lib}


def test_every_pose_and_every_move_between_two_keep_the_thumb_clear(hand) -> None:
    model, data = hand
    poses = _library()
    for name, q in poses.items():
        mjcf.set_coupled_pose(model, data, q, HAND)
        assert _thumb_clearance(model, data) >= CLEARANCE_M, name
    for a, b in itertools.permutations(poses, 2):
        for s in np.linspace(0.0, 1.0, 11)[1:-1]:  # both ends checked above
            q = {f: (1 - s) * poses[a][f] + s * poses[b][f] for f in NAMES}
            mjcf.set_coupled_pose(model, data, q, HAND)
            assert _thumb_clearance(model, data) >= CLEARANCE_M, (a, b, s)


@pytest.mark.parametrize("pose", ["pinch", "ok"])
def test_the_thumb_meets_the_index_in_pinch_and_ok(hand, pose: str) -> None:
    model, data = hand
    mjcf.set_coupled_pose(model, data, _library()[pose], HAND)
    gap = np.linalg.norm(data.site("thumb_tip").xpos - data.site("index_tip").xpos)
    radii = 2 * mjcf.load_layout().link_radius_fraction * HAND.fingers[1].geometry.R[2]
    assert gap - radii < 0.010  # the pads within 1 cm (measured: 4 and 8 mm)


def test_the_thumb_flexes_toward_the_fingers(hand) -> None:
    """Flexing, the thumb's tip moves across the palm toward the fingers (+y, +x), not away."""
    model, data = hand
    r1 = HAND.fingers[0].geometry.R[0]
    tips = []
    for flexion in (0.0, 0.4):
        mjcf.set_coupled_pose(model, data, {"thumb": flexion * math.pi / 2 * r1}, HAND)
        tips.append(data.site("thumb_tip").xpos.copy())
    moved = tips[1] - tips[0]
    assert moved[1] > 0.02 and moved[2] > 0.02
