"""Off-screen pictures of the MuJoCo hand (OSMesa) and ``utrf mjcf``."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
import mujoco
import numpy as np
import pytest

from utrf.cli import main
from utrf.models import mjcf, render
from utrf.models.geometry import HandGeometry

HAND = HandGeometry.default()


def _image(flexion: float) -> np.ndarray:
    model = mjcf.hand_model()
    data = mujoco.MjData(model)
    q = {f.name: float(flexion * f.geometry.q_range_m[1]) for f in HAND.fingers}
    mjcf.set_coupled_pose(model, data, q)
    return render.render(model, data, height=240, width=320)


def test_render_shows_the_hand_and_its_pose() -> None:
    open_hand, fist = _image(0.0), _image(0.85)
    assert open_hand.shape == (240, 320, 3) and open_hand.dtype == np.uint8
    # Not blank: the hand's grey links and dark palm against the light background.
    assert open_hand.std() > 10
    dark = (open_hand.mean(axis=2) < 110).mean()
    assert 0.005 < dark < 0.5
    # The pose shows: closing the fingers changes a good part of the picture.
    changed = (np.abs(open_hand.astype(int) - fist.astype(int)).sum(axis=2) > 60).mean()
    assert changed > 0.02


def test_render_refuses_a_picture_larger_than_the_buffer() -> None:
    model = mjcf.hand_model()
    with pytest.raises(render.RenderError, match="larger than the model's off-screen buffer"):
        render.render(model, mujoco.MjData(model), height=4000, width=4000)


def test_cli_writes_the_model_and_a_picture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    xml = tmp_path / "hand.xml"
    png = tmp_path / "fist.png"
    assert main(["mjcf", "--out", str(xml), "--render", str(png), "--pose", "fist"]) == 0
    model = mujoco.MjModel.from_xml_path(str(xml))
    assert model.nu == 10
    image = matplotlib.image.imread(png)
    assert image.shape[:2] == (480, 640) and image.std() > 0.03
    sheet = tmp_path / "sheet.png"
    argv = ["mjcf", "--render", str(sheet), "--pose", "open", "fist", "--width", "160"]
    assert main([*argv, "--height", "120"]) == 0
    assert matplotlib.image.imread(sheet).shape[1] >= 2 * 160  # two pictures side by side
    assert main(["mjcf", "--render", str(png), "--pose", "no-such-pose"]) == 2
    assert "no pose named 'no-such-pose'" in capsys.readouterr().err
    assert main(["mjcf", "--object", "egg"]) == 2
    assert "--object needs --object-pos-mm" in capsys.readouterr().err


def test_cli_prints_the_xml_with_an_object(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mjcf", "--object", "egg", "--object-pos-mm", "60", "0", "70"]) == 0
    model = mujoco.MjModel.from_xml_string(capsys.readouterr().out)
    assert model.body("egg").mass[0] == pytest.approx(0.06)


def test_cli_force_drive_and_bad_layout(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "force.xml"
    assert main(["mjcf", "--drive", "force", "--out", str(out)]) == 0
    model = mujoco.MjModel.from_xml_path(str(out))
    a = model.actuator("index_motor_a").id
    assert model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE
    np.testing.assert_allclose(model.actuator_ctrlrange[a], [-100.0, 100.0])
    layout = tmp_path / "layout.toml"
    text = (Path(mjcf.__file__).parent.parent / "data" / "mjcf.toml").read_text()
    layout.write_text(text.replace("size_m = [0.095, 0.090, 0.025]", "size_m = [0.1, 0.1]"))
    assert main(["mjcf", "--layout", str(layout)]) == 2
    assert "[palm]: size_m must be a list of 3 finite numbers" in capsys.readouterr().err
    assert main(["mjcf", "--layout", str(tmp_path / "missing.toml")]) == 2
    assert "no such MJCF layout file" in capsys.readouterr().err


@pytest.mark.parametrize("pose", ["open", "shaka"])
def test_every_fingertip_is_in_the_frame_where_it_is_drawn(pose: str) -> None:
    """``hand_at_labelled`` frames the whole hand (a straight finger reaches furthest) and says
    where each fingertip is: there the picture shows the tip's red site."""
    from utrf.poses import PoseLibrary

    theta2 = PoseLibrary.load()[pose].theta2(HAND)
    image, tips = render.hand_at_labelled(list(theta2), HAND, height=240, width=320)
    assert list(tips) == [f.name for f in HAND.fingers]
    red = (image[:, :, 0] > 170) & (image[:, :, 1] < 90) & (image[:, :, 2] < 90)
    rows, cols = np.nonzero(red)
    seen = 0
    for name, (col, row) in tips.items():
        assert 0.04 * 320 <= col <= 0.96 * 320 and 0.04 * 240 <= row <= 0.96 * 240, name
        near = np.hypot(cols - col, rows - row).min() if len(cols) else np.inf
        seen += near < 6  # a flexed tip may hide behind its finger; a straight one shows
    straight = sum(abs(t) < 0.1 for t in theta2)
    assert seen >= straight >= 2
