"""Setpoint planning: the loaded finger lands on target; unsafe plans are refused with reasons."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from utrf.models import kinematics, planning, statics, tendons
from utrf.models.geometry import FingerGeometry
from utrf.models.planning import PlanError, Target
from utrf.models.statics import Load


@settings(max_examples=25, deadline=None)
@given(f=st.floats(-0.6, 0.6), kg=st.floats(0.0, 0.3), model=st.sampled_from(statics.MODELS))
def test_loaded_tip_lands_on_the_target(f: float, kg: float, model: str) -> None:
    g = FingerGeometry.default()
    load = Load(payload_kg=kg)
    p = planning.plan(g, Target.flexion(f), load, model=model)
    target_tip = kinematics.tip_position(g, kinematics.q_from_flexion(g, f))
    # Re-solve the statics at the commanded q, independently of the plan's own result.
    loaded = statics.solve(g, p.q_command_m, load, model=model)
    miss = float(np.hypot(*(loaded.tip_m - target_tip)))
    assert miss == pytest.approx(p.tip_error_m, abs=1e-12)
    # No other command does better (a scan around the command).
    qs = p.q_command_m + np.linspace(-2e-4, 2e-4, 41)
    scan = statics.solve_batch(g, qs, payload_kg=kg, model=model).tip
    assert miss <= np.hypot(*(scan - target_tip).T).min() + 1e-9
    # And it does better than commanding the target's own q, unless there is nothing to correct.
    naive = statics.solve(g, p.q_target_m, load, model=model)
    assert miss <= float(np.hypot(*(naive.tip_m - target_tip))) + 1e-12


def test_theta2_match_puts_the_encoder_on_target(geom: FingerGeometry) -> None:
    target = Target.theta2(math.radians(30))
    p = planning.plan(geom, target, Load(payload_kg=0.2), match="theta2")
    loaded = statics.solve(geom, p.q_command_m, Load(payload_kg=0.2))
    assert loaded.theta_rad[1] == pytest.approx(math.radians(30), abs=1e-10)
    assert p.theta2_setpoint_rad == pytest.approx(math.radians(30), abs=1e-10)


def test_firmware_targets_map_back_to_the_setpoint(geom: FingerGeometry) -> None:
    p = planning.plan(geom, Target.flexion(0.4), Load(payload_kg=0.2))
    ft = p.firmware_targets
    # The firmware maps each kind to a Joint-2 angle through the rigid coupling.
    assert kinematics.theta2_from_q(geom, ft["TENDON_Q"]) == pytest.approx(ft["JOINT2_ANGLE"])
    q_from_flexion = kinematics.q_from_flexion(geom, ft["FLEXION"])
    assert kinematics.theta2_from_q(geom, q_from_flexion) == pytest.approx(ft["JOINT2_ANGLE"])
    assert ft["JOINT2_ANGLE"] == p.statics.theta_rad[1]


def test_plan_predicts_tensions_and_motor_force(geom: FingerGeometry) -> None:
    p = planning.plan(geom, Target.flexion(0.0), Load(payload_kg=0.2))
    assert p.safe and p.reasons == ()
    assert p.motor_force_n[0] == pytest.approx(p.tensions_n[0])
    assert p.statics.loaded_tendons == (1, 2, 3)
    j = p.to_json()
    for key in (
        "q_command_m",
        "tensions_n",
        "motor_force_n",
        "safe",
        "reasons",
        "firmware_targets",
    ):
        assert key in j


def test_refuses_an_overloaded_motor_with_the_reason(geom: FingerGeometry) -> None:
    p = planning.plan(geom, Target.flexion(0.0), Load(payload_kg=1.0))
    assert not p.safe
    assert any("motor A (Tendon 1) must pull" in r and "rated 150 N" in r for r in p.reasons)


def test_refuses_an_overstressed_tendon(geom: FingerGeometry) -> None:
    limits = tendons.Limits(actuator_rated_force_n=1e6)
    p = planning.plan(geom, Target.flexion(0.0), Load(payload_kg=3.0), limits=limits)
    assert not p.safe
    assert any(
        r.startswith(("Tendon 1 is overstressed", "Tendon 1 would break")) for r in p.reasons
    )
    assert not any("motor" in r for r in p.reasons)


def test_refuses_when_joint1_would_leave_its_range(geom: FingerGeometry) -> None:
    # At full flexion a payload that needs more pull takes θ1 past 90°.
    p = planning.plan(
        geom, Target.flexion(1.0), Load(tip_force_n=(0.0, 0.0), tip_moment_nm=-0.3, gravity=False)
    )
    assert not p.safe and any(
        r.startswith("theta1 =") and "outside theta1_range" in r for r in p.reasons
    )


def test_tip_targets_use_the_nearest_reachable_point(geom: FingerGeometry) -> None:
    tip = kinematics.tip_position(geom, 0.003)
    p = planning.plan(geom, Target.tip(*tip), Load(payload_kg=0.1))
    assert p.q_target_m == pytest.approx(0.003, abs=1e-9)
    off = planning.plan(geom, Target.tip(0.5, 0.0), Load(gravity=False))
    assert any("nearest reachable" in w for w in off.warnings)
    np.testing.assert_allclose(off.target_tip_m, [0.17, 0.0], atol=1e-8)


@pytest.mark.parametrize(
    ("target", "match"),
    [
        (lambda: Target.flexion(1.5), "outside the finger's range"),
        (lambda: Target.theta2(math.radians(170)), "outside the finger's range"),
        (lambda: Target("pose", 1.0), "Target.kind must be one of"),
        (lambda: Target.tip(0.1, float("nan")), "finite"),
        (lambda: Target.flexion(float("inf")), "finite"),
    ],
)
def test_bad_targets_are_named(geom: FingerGeometry, target, match: str) -> None:
    with pytest.raises(PlanError, match=match):
        planning.plan(geom, target(), Load())


def test_named_poses_come_from_the_pose_library(geom: FingerGeometry) -> None:
    from utrf.poses import PoseLibrary

    lib = PoseLibrary.load(include_user=False)
    fist = planning.named_pose_target("fist", "index", lib)
    assert fist == Target(lib["fist"].targets["index"].kind, lib["fist"].targets["index"].value)
    p = planning.plan(geom, planning.named_pose_target("open", "index", lib), Load(payload_kg=0.1))
    assert p.q_target_m == 0.0
    with pytest.raises(PlanError, match="no pose named 'fits'"):
        planning.named_pose_target("fits", "index", lib)
    with pytest.raises(PlanError, match="no finger 'pinky'"):
        planning.named_pose_target("fist", "pinky", lib)
