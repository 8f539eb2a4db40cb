"""The models' CLI: JSON in SI with the issue's keys, human tables, and clear errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from utrf.cli import main
from utrf.models import kinematics, planning, statics
from utrf.models.geometry import FingerGeometry, HandGeometry


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code, out, err = run(capsys, *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def test_kinematics_json(capsys: pytest.CaptureFixture[str]) -> None:
    g = FingerGeometry.default()
    out = run_json(capsys, "kinematics", "--q", "0.003")
    fk = kinematics.forward(g, 0.003)
    np.testing.assert_allclose(out["theta_rad"], fk.theta)
    np.testing.assert_allclose(out["tip_m"], fk.tip)
    np.testing.assert_allclose(out["jacobian"], fk.jacobian)
    theta2 = 0.003 / g.guide_radii_m[1]
    by_deg = run_json(capsys, "kinematics", "--theta2-deg", str(math.degrees(theta2)))
    np.testing.assert_allclose(by_deg["tip_m"], fk.tip, atol=1e-12)
    by_tip = run_json(capsys, "kinematics", "--tip-mm", *(str(v * 1e3) for v in fk.tip))
    assert by_tip["tip_distance_m"] < 1e-8


def test_kinematics_table_says_its_units(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, out, _ = run(capsys, "kinematics", "--flexion", "0.9")
    assert code == 0 and "(deg, relative)" in out and "tip (mm)" in out
    assert "would leave its guide" not in out  # the default stays coupled over its range
    steep = FingerGeometry.from_dict(
        {**FingerGeometry.default().to_dict(), "guide_radii_m": [0.010, 0.008, 0.006]}
    )
    f = tmp_path / "steep.toml"
    f.write_text("[finger]\n" + "".join(f"{k} = {v!r}\n" for k, v in steep.to_dict().items()))
    code, out, _ = run(capsys, "kinematics", "--flexion", "0.9", "--finger", str(f))
    assert code == 0 and "would leave its guide" in out  # 10/8/6 mm unwraps at flexion 0.70


def test_statics_json_has_the_issue_keys(capsys: pytest.CaptureFixture[str]) -> None:
    out = run_json(
        capsys,
        "statics",
        "--q",
        "0.002",
        "--load-kg",
        "0.5",
        "--force-n",
        "1",
        "-2",
        "--moment-nm",
        "0.05",
        "--model",
        "printed",
    )
    for key in ("theta_rad", "tip_m", "tensions_n", "tip_deflection_m", "iterations", "model"):
        assert key in out
    load = statics.Load(payload_kg=0.5, tip_force_n=(1.0, -2.0), tip_moment_nm=0.05)
    res = statics.solve(FingerGeometry.default(), 0.002, load, model="printed")
    assert out["model"] == "printed"
    np.testing.assert_allclose(out["tip_m"], res.tip_m)
    np.testing.assert_allclose(out["tensions_n"], res.tensions_n)


def test_statics_compare_and_verify(capsys: pytest.CaptureFixture[str]) -> None:
    out = run_json(capsys, "statics", "--load-kg", "1", "--compare", "--verify")
    assert out["compare"]["model"] == "printed" and out["compare"]["tip_difference_m"] > 1e-3
    assert out["verify"]["tip_difference_m"] < 1e-8
    code, text, _ = run(capsys, "statics", "--load-kg", "3")
    assert code == 0 and "warning: Tendon 1 would break" in text and "tension N" in text


def test_statics_solver_options_reach_the_solver(capsys: pytest.CaptureFixture[str]) -> None:
    g, load = FingerGeometry.default(), statics.Load(payload_kg=3.0)
    aitken = statics.solve(g, 0.0, load, relaxation="aitken", threshold_m=1e-12)
    plain = statics.solve(g, 0.0, load, relaxation="none", threshold_m=1e-12)
    assert aitken.iterations != plain.iterations  # so the option shows in the count
    for rx, ref in (("aitken", aitken), ("none", plain)):
        out = run_json(
            capsys, "statics", "--load-kg", "3", "--relaxation", rx, "--threshold-m", "1e-12"
        )
        assert out["iterations"] == ref.iterations and out["threshold_m"] == 1e-12
    # --compare solves the other model with the same options.
    out = run_json(capsys, "statics", "--load-kg", "3", "--compare", "--threshold-m", "1e-3")
    printed = statics.solve(g, 0.0, load, model="printed", threshold_m=1e-3)
    assert printed.iterations < statics.solve(g, 0.0, load, model="printed").iterations
    np.testing.assert_allclose(out["compare"]["tip_m"], printed.tip_m)


def test_thumb_by_name_or_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    thumb = HandGeometry.default().fingers[0].geometry
    out = run_json(capsys, "kinematics", "--q", "0", "--finger", "thumb")
    assert out["tip_m"][0] == pytest.approx(thumb.total_length_m)
    f = tmp_path / "t.toml"
    f.write_text(
        Path(thumb.source).read_text().replace("[0.055, 0.045, 0.035]", "[0.05, 0.04, 0.03]")
    )
    out = run_json(capsys, "kinematics", "--q", "0", "--finger", str(f))
    assert out["tip_m"][0] == pytest.approx(0.12)


def test_bad_input_exits_2_naming_the_problem(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, _, err = run(capsys, "kinematics", "--q", "0", "--finger", "pinky")
    assert code == 2 and "no finger named 'pinky'" in err
    code, _, err = run(capsys, "statics", "--load-kg", "-1")
    assert code == 2 and "payload_kg must be >= 0" in err
    bad = tmp_path / "bad.toml"
    bad.write_text("[finger]\nlink_lengths_m = [1, 2]\n")
    code, _, err = run(capsys, "statics", "--finger", str(bad))
    assert code == 2 and "bad.toml" in err
    code, _, err = run(capsys, "calibrate", str(tmp_path / "none.csv"))
    assert code == 2 and "no such file" in err


def test_workspace_and_stiffness_figures(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out = run_json(capsys, "workspace", "--out", str(tmp_path / "w.png"), "--resolution-mm", "1")
    assert (tmp_path / "w.png").stat().st_size > 1000
    assert out["areas"]["link_areas_m2"][0] == pytest.approx(math.pi * 0.07**2 / 2, rel=0.01)
    out = run_json(capsys, "stiffness", "--out", str(tmp_path / "s.png"))
    assert (tmp_path / "s.png").stat().st_size > 1000
    serial = out["models"]["serial"]
    assert serial["loads_kg"] == [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    assert serial["stiffness_n_per_m"] == pytest.approx(3 * 9.80665 / serial["deflection_m"][-1])
    assert out["paper"]["deflection_m"] == 0.024386


def test_calibrate(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    p = tmp_path / "d.csv"
    p.write_text("load_kg,deflection_mm\n1,8.0\n2,16.2\n3,24.1\n")
    out = run_json(capsys, "calibrate", str(p))
    assert out["fitted"] == ["modulus"] and out["rows"] == 3
    assert out["max_error_pct"] == pytest.approx(100 * out["max_error_m"] / 0.17)
    code, text, _ = run(capsys, "calibrate", str(p), "--fit", "modulus,radius_scale")
    assert code == 0 and "% of" in text


def test_plan_safe_refused_and_named(capsys: pytest.CaptureFixture[str]) -> None:
    out = run_json(capsys, "plan", "--flexion", "0.3", "--load-kg", "0.1")
    ref = planning.plan(
        FingerGeometry.default(), planning.Target.flexion(0.3), statics.Load(payload_kg=0.1)
    )
    assert out["safe"] and out["q_command_m"] == pytest.approx(ref.q_command_m, abs=1e-12)
    code, text, _ = run(capsys, "plan", "--flexion", "0", "--load-kg", "2")
    assert code == 3 and "REFUSED" in text and "motor A (Tendon 1) must pull" in text
    code, _, err = run(capsys, "plan", "fsit", "--load-kg", "0.1")
    assert code == 2 and "no pose named 'fsit'" in err


def test_plan_a_named_pose_plans_every_finger_with_its_geometry(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from utrf.poses import PoseLibrary

    hand = HandGeometry.default()
    q = PoseLibrary.load(hand=hand, include_user=False)["rock-and-roll"].q(hand)
    out = run_json(capsys, "plan", "rock-and-roll", "--load-kg", "0.05")
    assert out["pose"] == "rock-and-roll"
    assert list(out["fingers"]) == [f.name for f in hand.fingers]
    for i, f in enumerate(hand.fingers):
        assert out["fingers"][f.name]["q_target_m"] == pytest.approx(q[i], abs=1e-12)
    one = run_json(capsys, "plan", "rock-and-roll", "--finger-name", "thumb", "--load-kg", "0.05")
    assert list(one["fingers"]) == ["thumb"]
    code, _, err = run(capsys, "plan", "--load-kg", "0.1")
    assert code == 2 and "give a pose" in err
