"""The MuJoCo hand (utrf.models.mjcf): structure, kinematics and loaded statics against the
models, tension-only tendons, the actuators' limits, and stable time-stepping."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from utrf.models import kinematics, mjcf, mjcf_statics, statics, tendons
from utrf.models.geometry import FingerSpec, HandGeometry

HAND = HandGeometry.default()


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return mjcf.hand_model()


def test_names_and_constants_come_from_the_geometry(model: mujoco.MjModel) -> None:
    for spec in HAND.fingers:
        f, g = spec.name, spec.geometry
        for k in range(3):
            assert model.joint(f"{f}_j{k + 1}").type == mujoco.mjtJoint.mjJNT_HINGE
            body = model.body(f"{f}_link{k + 1}")
            assert body.mass[0] == pytest.approx(g.link_masses_kg[k], rel=1e-12)
            com = g.link_com_fraction[k] * g.link_lengths_m[k]
            np.testing.assert_allclose(body.ipos, [com, 0, 0], atol=1e-15)
        np.testing.assert_allclose(model.site(f"{f}_tip").pos, [g.link_lengths_m[2], 0, 0])
        k_expected = tendons.stiffnesses(g)
        for t in range(1, 7):
            i = model.tendon(f"{f}_t{t}").id
            assert model.tendon_stiffness[i] == pytest.approx(k_expected[(t - 1) % 3], rel=1e-12)
            np.testing.assert_array_equal(model.tendon_lengthspring[i], [mjcf._SLACK_M, 0.0])
        assert model.actuator(f"{f}_motor_a").trntype == mujoco.mjtTrn.mjTRN_JOINT
        assert model.actuator(f"{f}_motor_b") is not None
    assert model.nu == 10 and model.ntendon == 30


def test_xml_round_trips_through_a_file(tmp_path: Path) -> None:
    path = tmp_path / "hand.xml"
    path.write_text(mjcf.hand_xml())
    loaded = mujoco.MjModel.from_xml_path(str(path))
    assert loaded.nq == mjcf.hand_model().nq


@pytest.mark.parametrize("finger", [f.name for f in HAND.fingers])
def test_tip_matches_kinematics_at_coupled_poses(model: mujoco.MjModel, finger: str) -> None:
    g = HAND.fingers[HAND.index(finger)].geometry
    data = mujoco.MjData(model)
    rng = np.random.default_rng(10 + HAND.index(finger))
    for q in rng.uniform(*g.q_range_m, size=50):
        mjcf.set_coupled_pose(model, data, {finger: q})
        j1 = data.joint(f"{finger}_j1").xanchor
        tip = data.site(f"{finger}_tip").xpos
        expected = kinematics.tip_position(g, q)
        assert abs(np.linalg.norm(tip - j1) - np.linalg.norm(expected)) < 1e-6
        origin, rot = mjcf.finger_frame(model, data, finger)
        np.testing.assert_allclose(rot.T @ (tip - origin), [*expected, 0.0], atol=1e-12)


def _random_load(rng: np.random.Generator) -> statics.Load:
    return statics.Load(
        payload_kg=float(rng.uniform(0.0, 0.5)),
        tip_force_n=(float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5))),
        tip_moment_nm=float(rng.uniform(-0.1, 0.1)),
        grasp_force_n=float(rng.uniform(0.0, 5.0)),
        gravity=bool(rng.integers(0, 2)),
    )


def _agreement(g, e: mjcf_statics.MjEquilibrium, s: statics.StaticsResult) -> float:
    """The largest relative disagreement: joint deflections, tip deflection, net tensions."""
    rigid = s.q_m / g.R
    d_theta = np.abs((e.theta_rad - rigid) - (s.theta_rad - rigid)).max()
    d_theta /= np.abs(s.theta_rad - rigid).max()
    d_tip = np.linalg.norm(e.tip_m - s.tip_m) / np.linalg.norm(s.tip_m - s.tip_unloaded_m)
    d_net = np.abs(e.net_tensions_n - s.net_tensions_n).max() / np.abs(s.net_tensions_n).max()
    return float(max(d_theta, d_tip, d_net))


def _check_statics(model: mujoco.MjModel, hand: HandGeometry, finger: str, seed: int) -> None:
    g = hand.fingers[hand.index(finger)].geometry
    rng = np.random.default_rng(seed)
    for _ in range(12):
        q = float(rng.uniform(*g.q_range_m))
        load = _random_load(rng)
        e = mjcf_statics.equilibrium(model, finger, q, load, hand)
        s = statics.solve(g, q, load, model="serial", threshold_m=1e-15)
        assert s.converged
        assert _agreement(g, e, s) < 1e-6, (finger, q, load)


@pytest.mark.parametrize("finger", [f.name for f in HAND.fingers])
def test_loaded_statics_agree_with_the_serial_model(model: mujoco.MjModel, finger: str) -> None:
    _check_statics(model, HAND, finger, seed=100 + HAND.index(finger))


def test_statics_of_a_rotary_finger_agree_too() -> None:
    fingers = list(HAND.fingers)
    fingers[1] = FingerSpec(name="index", geometry=fingers[1].geometry, actuation="rotary")
    hand = dataclasses.replace(HAND, fingers=tuple(fingers))
    model = mjcf.hand_model(hand)
    assert model.joint("index_pulley").type == mujoco.mjtJoint.mjJNT_HINGE
    assert model.actuator("index_motor") is not None
    with pytest.raises(KeyError):
        model.actuator("index_motor_b")
    _check_statics(model, hand, "index", seed=7)


def test_statics_agreement_is_sensitive_to_the_tendon_stiffness() -> None:
    """A 1e-4 error in one coupling tendon's stiffness is seen by the check."""
    model = mjcf.hand_model()
    t = model.tendon("middle_t3").id
    model.tendon_stiffness[t] *= 1.0 + 1e-4
    g = HAND.fingers[HAND.index("middle")].geometry
    load = statics.Load(payload_kg=0.3)
    e = mjcf_statics.equilibrium(model, "middle", 0.004, load)
    s = statics.solve(g, 0.004, load, threshold_m=1e-15)
    assert _agreement(g, e, s) > 1e-6


def test_tendons_pull_only(model: mujoco.MjModel) -> None:
    """A payload loads the flexion group and leaves the extension group slack; a push up does
    the opposite."""
    data = mujoco.MjData(model)
    for load, taut in (
        (statics.Load(payload_kg=0.5), (1, 2, 3)),
        (statics.Load(tip_force_n=(0.0, 8.0), gravity=False), (4, 5, 6)),
    ):
        e = mjcf_statics.equilibrium(model, "ring", 0.0, load)
        mjcf.set_coupled_pose(model, data, {"ring": 0.0})
        data.qpos[[model.joint(f"ring_j{k}").qposadr[0] for k in (1, 2, 3)]] = e.theta_rad
        mujoco.mj_forward(model, data)
        for t in range(1, 7):
            tension = mjcf_statics._tension(model, data, f"ring_t{t}")
            if t in taut:
                assert tension > 1.0
            else:
                assert tension == 0.0


def test_motor_constants_are_the_emulators() -> None:
    from utrf.emulator.plant_params import MotorParams

    layout = mjcf.load_layout()
    p = MotorParams()
    for field in dataclasses.fields(layout.motor):
        assert getattr(layout.motor, field.name) == getattr(p, field.name), field.name


def test_full_duty_respects_speed_force_and_travel() -> None:
    """Motor A at duty +1 and B at −1: the carriages run no faster than the no-load speed,
    the finger stops at Joint 1's limit with motor A stalled against it (its force limit),
    and motor B stops at the end of its stroke."""
    model = mjcf.hand_model()
    layout = mjcf.load_layout()
    data = mujoco.MjData(model)
    mjcf.set_coupled_pose(model, data, {"index": 0.0})
    a, b = model.actuator("index_motor_a").id, model.actuator("index_motor_b").id
    data.ctrl[a], data.ctrl[b] = 1.0, -1.0
    xa, xb = model.joint("index_xa"), model.joint("index_xb")
    top = 0.0
    for _ in range(int(1.5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
        top = max(top, data.qvel[xa.dofadr[0]], -data.qvel[xb.dofadr[0]])
    assert np.all(np.isfinite(data.qpos))
    assert 0.8 * layout.motor.no_load_speed_m_s < top <= layout.motor.no_load_speed_m_s
    j1 = data.qpos[model.joint("index_j1").qposadr[0]]
    assert j1 == pytest.approx(math.pi / 2, abs=math.radians(1.0))
    assert data.actuator_force[a] == pytest.approx(layout.motor.stall_force_n, rel=0.02)
    assert data.qpos[xb.qposadr[0]] == pytest.approx(layout.motor.stroke_m[0], abs=0.5e-3)


def _kick_and_settle(model: mujoco.MjModel) -> mujoco.MjData:
    """Every finger at q = 6 mm, joints kicked to ±20 rad/s, no gravity, 0.5 s of steps."""
    data = mujoco.MjData(model)
    mjcf.set_coupled_pose(model, data, {f.name: 0.006 for f in HAND.fingers})
    rng = np.random.default_rng(3)
    dofs = [model.joint(f"{f.name}_j{k}").dofadr[0] for f in HAND.fingers for k in (1, 2, 3)]
    data.qvel[dofs] = rng.uniform(-20, 20, len(dofs))
    model.opt.gravity[:] = 0.0
    for _ in range(int(0.5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    return data


def test_default_timestep_is_stable_and_damps_the_coupling() -> None:
    """Kicked joints at the default step settle back onto the tendon equilibrium."""
    model = mjcf.hand_model(drive="force")
    data = _kick_and_settle(model)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0  # no blow-up and reset
    for f in HAND.fingers:
        g = f.geometry
        theta = np.array([data.qpos[model.joint(f"{f.name}_j{k}").qposadr[0]] for k in (1, 2, 3)])
        assert theta[0] * g.R[0] > 0.003  # still near the pose, not reset to qpos0
        # The coupling holds again (R_k θ_k equal along the chain: the stiff mode has died
        # out), and at rest with no load neither actuating tendon is stretched.
        np.testing.assert_allclose(theta * g.R, theta[0] * g.R[0], atol=1e-9)
        for t in ("t1", "t4"):
            assert data.ten_length[model.tendon(f"{f.name}_{t}").id] < 1e-7


def test_too_little_coupling_damping_is_unstable_at_the_default_step(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Why the coupling damping is what it is: a fifth of it blows up at the same step."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warning to MUJOCO_LOG.TXT here
    model = mjcf.hand_model(drive="force")
    model.tendon_damping[model.tendon_damping > 0] /= 5.0
    data = _kick_and_settle(model)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0


def test_bad_layout_names_the_field(tmp_path: Path) -> None:
    text = (Path(mjcf.__file__).parent.parent / "data" / "mjcf.toml").read_text()
    bad = tmp_path / "layout.toml"
    bad.write_text(text.replace('integrator = "implicitfast"', 'integrator = "leapfrog"'))
    with pytest.raises(mjcf.MjcfError, match=r"\[dynamics\]: integrator must be one of"):
        mjcf.load_layout(bad)
    bad.write_text(text.replace("stall_force_n = 100.0", "stall_force_n = -1"))
    with pytest.raises(mjcf.MjcfError, match=r"\[motor\]: stall_force_n must be > 0"):
        mjcf.load_layout(bad)
    bad.write_text(text.replace("coulomb_friction_n = 1.5", "coulomb_friction_n = -0.1"))
    with pytest.raises(mjcf.MjcfError, match=r"\[motor\]: coulomb_friction_n must be >= 0"):
        mjcf.load_layout(bad)
    bad.write_text(text.replace("coulomb_friction_n = 1.5", "coulomb_friction_n = 0"))
    assert mjcf.load_layout(bad).motor.coulomb_friction_n == 0.0
    bad.write_text(text.replace("[fingers.ring]", "[fingers.ringg]"))
    with pytest.raises(mjcf.MjcfError, match=r"no \[fingers.NAME\] placement for \['ring'\]"):
        mjcf.hand_xml(layout=mjcf.load_layout(bad))
    with pytest.raises(mjcf.MjcfError, match="drive must be one of"):
        mjcf.hand_xml(drive="torque")


def test_fingers_in_parallel_planes_apart_are_left_out_of_each_others_contacts() -> None:
    """Index..little flex in parallel planes 22 mm apart (capsules <= 9 mm): never touching;
    the thumb's plane is not parallel to theirs, so its pairs stay."""
    hand = HandGeometry.default()
    layout = mjcf.load_layout()
    apart = mjcf.never_touching(hand, layout)
    bit = {f.name: mjcf.FINGER_CONTYPE << i for i, f in enumerate(hand.fingers)}
    long_fingers = ("index", "middle", "ring", "little")
    for i, f in enumerate(hand.fingers):
        want = 0 if f.name == "thumb" else sum(bit[n] for n in long_fingers if n != f.name)
        assert apart[i] == want, f.name
    model = mujoco.MjModel.from_xml_string(mjcf.hand_xml(hand, layout))

    def collide(a: str, b: str) -> bool:
        ga, gb = (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in (a, b))
        ta, ca = int(model.geom_contype[ga]), int(model.geom_conaffinity[ga])
        tb, cb = int(model.geom_contype[gb]), int(model.geom_conaffinity[gb])
        return bool(ta & cb or tb & ca)

    assert not collide("index_link3", "middle_link3")
    assert not collide("ring_link1", "little_link2")
    assert collide("thumb_link3", "index_link3")
    assert collide("little_link3", "palm")
    # moved so their planes are close, two long fingers collide again
    near = dataclasses.replace(layout.fingers["middle"], position_m=(0.0, -0.025, 0.0))
    close = dataclasses.replace(layout, fingers={**layout.fingers, "middle": near})
    assert not mjcf.never_touching(hand, close)[1] & bit["middle"]
