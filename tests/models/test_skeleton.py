"""The dashboard's and the recording's 3D hand: the MuJoCo model's joints at the same angles."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from utrf.models import mjcf
from utrf.models.geometry import HandGeometry
from utrf.models.skeleton import HandSkeleton


@pytest.mark.parametrize("flex", [0.0, 0.4, 0.9])
def test_skeleton_tips_are_the_mjcf_tips(flex: float) -> None:
    hand = HandGeometry.default()
    skel = HandSkeleton(hand)
    theta2 = [flex * f.geometry.theta2_range_rad[1] for f in hand.fingers]
    model = mujoco.MjModel.from_xml_string(mjcf.hand_xml(hand))
    data = mujoco.MjData(model)
    q = {f.name: t * f.geometry.guide_radii_m[1] for f, t in zip(hand.fingers, theta2, strict=True)}
    mjcf.set_coupled_pose(model, data, q, hand)
    pts = skel.points(theta2)
    for i, f in enumerate(hand.fingers):
        np.testing.assert_allclose(pts[i, -1], data.site(f"{f.name}_tip").xpos, atol=1e-6)
        np.testing.assert_allclose(pts[i, 0], mjcf.finger_frame(model, data, f.name)[0], atol=1e-6)


def test_skeleton_names_a_wrong_count() -> None:
    with pytest.raises(ValueError, match="need 5 Joint-2 angles, got 2"):
        HandSkeleton().points([0.0, 0.1])
