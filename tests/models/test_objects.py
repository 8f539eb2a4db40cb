"""The object library (utrf.models.objects): data, errors, and objects added to the hand."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from utrf.models import mjcf, objects


def test_library_has_the_kinds_the_paper_grasps() -> None:
    lib = objects.load_objects()
    shapes = {o.shape for o in lib.values()}
    assert {"cylinder", "sphere", "box"} <= shapes
    assert {"bottle", "ball", "box", "egg"} <= set(lib)
    assert lib["egg"].fragile and lib["egg"].breaking_force_n > 0
    assert not lib["bottle"].fragile


@pytest.mark.parametrize("name", ["bottle", "ball", "box", "egg"])
def test_object_added_at_its_pose_falls_freely(name: str) -> None:
    obj = objects.get_object(name)
    quat = np.array([np.cos(0.3), np.sin(0.3), 0.0, 0.0])
    xml = objects.add_object(mjcf.hand_xml(), obj, (0.3, 0.2, 0.5), quat)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    body = data.body(name)
    np.testing.assert_allclose(body.xpos, [0.3, 0.2, 0.5], atol=1e-12)
    np.testing.assert_allclose(body.xquat, quat, atol=1e-12)
    assert model.body(name).mass[0] == pytest.approx(obj.mass_kg)
    geom = model.geom(name)
    assert geom.friction[0] == pytest.approx(obj.friction)
    assert geom.size[: len(obj.size_m)] == pytest.approx(obj.size_m)
    for _ in range(100):  # far from the hand: it falls freely
        mujoco.mj_step(model, data)
    t = data.time
    assert data.body(name).xpos[2] == pytest.approx(0.5 - 0.5 * 9.80665 * t**2, abs=2e-3)


def test_an_object_on_the_palm_rests_on_it() -> None:
    """The object collides with the palm: dropped onto it, it stops there."""
    box = objects.get_object("box")
    xml = objects.add_object(mjcf.hand_xml(), box, (-0.045, 0.0, 0.06))
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for _ in range(int(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert data.body("box").xpos[2] == pytest.approx(box.size_m[2], abs=2e-3)


def test_bad_objects_are_named(tmp_path: Path) -> None:
    path = tmp_path / "o.toml"
    path.write_text('[object.can]\nshape = "cone"\nsize_m = [0.1]\nmass_kg = 1\nfriction = 1\n')
    with pytest.raises(objects.ObjectError, match=r"\[object.can\]: shape must be one of"):
        objects.load_objects(path)
    path.write_text('[object.can]\nshape = "box"\nsize_m = [0.1]\nmass_kg = 1\nfriction = 1\n')
    with pytest.raises(objects.ObjectError, match=r"size_m of a box must be 3 number"):
        objects.load_objects(path)
    path.write_text('[object.can]\nshape = "sphere"\nsize_m = [0.1]\nmass_kg = 0\nfriction = 1\n')
    with pytest.raises(objects.ObjectError, match=r"mass_kg must be a number > 0"):
        objects.load_objects(path)
    with pytest.raises(objects.ObjectError, match="no object named 'anvil'"):
        objects.get_object("anvil")
    xml = objects.add_object(mjcf.hand_xml(), "ball", (0, 0, 0.2))
    with pytest.raises(objects.ObjectError, match="already has an element named 'ball'"):
        objects.add_object(xml, "ball", (0, 0, 0.3))
    with pytest.raises(objects.ObjectError, match="unit quaternion"):
        objects.add_object(mjcf.hand_xml(), "ball", (0, 0, 0.3), (1, 1, 0, 0))


def test_each_object_says_how_the_hand_takes_it() -> None:
    """Placement and grasp are data: every object of the library rests on the palm-up hand
    (its lowest point on the palm's top face, z = 0) with a grasp pose of the pose library."""
    from utrf.poses import PoseLibrary

    poses = PoseLibrary.load(include_user=False)
    for obj in objects.load_objects().values():
        pose = poses.get(obj.grasp_pose or "")
        assert pose is not None and pose.grasp is not None, obj.name
        assert obj.rest_position_m is not None
        xml = objects.add_object(mjcf.hand_xml(), obj, obj.rest_position_m, obj.rest_quat)
        model = mujoco.MjModel.from_xml_string(xml)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        lowest = data.geom(obj.name).xpos[2] - _half_height(model, data, obj.name)
        assert lowest == pytest.approx(0.0, abs=5e-4), obj.name


def test_each_object_closes_with_its_own_pose() -> None:
    """Issue 22: no object borrows another's grasp (the box once closed with grasp-bottle),
    and each description names the pose it closes with."""
    lib = objects.load_objects()
    named = {name: obj.grasp_pose for name, obj in lib.items()}
    assert len(set(named.values())) == len(named), named
    for name, obj in lib.items():
        assert f"pose {obj.grasp_pose})" in obj.description, name


def _half_height(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> float:
    """The geom's half extent along world z (its axis-aligned box)."""
    geom = model.geom(name)
    rot = data.geom(name).xmat.reshape(3, 3)
    size = np.array(geom.size)
    if geom.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(size[0])
    if geom.type[0] == mujoco.mjtGeom.mjGEOM_CYLINDER:
        axis = rot[:, 2]
        return float(size[1] * abs(axis[2]) + size[0] * np.hypot(axis[0], axis[1]))
    return float(np.abs(rot[2]) @ size)


def test_bad_grasp_data_is_named(tmp_path: Path) -> None:
    path = tmp_path / "o.toml"
    base = '[object.can]\nshape = "sphere"\nsize_m = [0.1]\nmass_kg = 1\nfriction = 1\n'
    path.write_text(base + 'rest_axis = "w"\n')
    with pytest.raises(objects.ObjectError, match=r"\[object.can\]: rest_axis must be one of"):
        objects.load_objects(path)
    path.write_text(base + "grasp_effort = 1.5\n")
    with pytest.raises(objects.ObjectError, match=r"grasp_effort must lie in \(0, 1\]"):
        objects.load_objects(path)
    path.write_text(base + "rest_position_m = [0, 0]\n")
    with pytest.raises(objects.ObjectError, match=r"rest_position_m must be 3 finite numbers"):
        objects.load_objects(path)
