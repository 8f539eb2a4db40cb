"""The real firmware driving the MuJoCo hand (``EmulatedBoard(plant="mujoco")``): the closed
loop, the encoder's voltage, the TB6612 truth table on the actuators, determinism for a seed,
fault injection, and an object in the hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from emu_helpers import QUIET

from utrf.emulator import EmulatedBoard, PlantParams
from utrf.emulator.mujoco_plant import MujocoPlant
from utrf.hand.simlink import SimLink
from utrf.protocol import messages as m

ALL = 0b11111
COUNT_RAD = 2 * np.pi / (1024 * 0.8)  # one 10-bit ADC count over the 80 % band: 7.7 mrad


def link_for(board: EmulatedBoard) -> SimLink:
    link = SimLink(board)
    link.handshake()
    link.request(m.ClearFaults(mask=ALL))
    return link


def set_modes(link: SimLink, mode: m.ControlMode, mask: int = ALL, duty: float = 0.0) -> None:
    link.request(m.SetMode(mask=mask, mode=(mode,) * 5, duty=(duty,) * 5, effort=(0.0,) * 5))


@pytest.fixture
def board(firmware_elf: Path):
    with EmulatedBoard(firmware_elf, realtime=False, plant="mujoco", exchange_period=1e-3) as b:
        yield b


def test_position_control_closes_the_loop_through_mujoco(board: EmulatedBoard) -> None:
    link = link_for(board)
    targets = (0.3, 0.5, 0.7, 0.9, 1.1)
    link.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=targets))
    set_modes(link, m.ControlMode.POSITION)
    link.sleep(2.0)
    state = link.request(m.GetState())
    assert not any(link.request(m.GetStatus()).faults)
    np.testing.assert_allclose(board.theta2, targets, atol=0.03)  # MuJoCo's own joint angle
    np.testing.assert_allclose(state.theta2, board.theta2, atol=2 * COUNT_RAD)  # as read
    # the coupling: θ1 and θ3 follow θ2 through the tendons (θ_i R_i equal)
    q = board.theta * np.array([f.geometry.guide_radii_m for f in board.plant.hand.fingers])
    np.testing.assert_allclose(q[:, 0], q[:, 1], atol=1e-3)
    np.testing.assert_allclose(q[:, 2], q[:, 1], atol=1e-3)


def test_the_encoder_voltage_is_the_as5600s(firmware_elf: Path) -> None:
    with EmulatedBoard(
        firmware_elf, realtime=False, plant="mujoco", plant_params=QUIET, exchange_period=1e-3
    ) as b:
        angles = [-0.8, -0.2, 0.3, 0.9, 1.4]
        for f, a in enumerate(angles):
            b.plant.set_theta2(f, a)
        volts = b.plant.encoder_volts()
        # 12 bits over one turn, 10-90 % of 5 V, offset π: the straight finger at 2.5 V
        expect = 0.5 + 4.0 / 4096 * np.floor((np.array(angles) + np.pi) / (2 * np.pi) * 4096)
        np.testing.assert_allclose(volts, expect, atol=1e-12)
        link = link_for(b)
        state = link.request(m.GetState())
        np.testing.assert_allclose(state.theta2, b.theta2, atol=COUNT_RAD)


def test_the_truth_table_drives_the_actuators(board: EmulatedBoard) -> None:
    link = link_for(board)
    link.request(
        m.SetMode(
            mask=0b00110,
            mode=(m.ControlMode.COAST, m.ControlMode.DUTY, m.ControlMode.DUTY)
            + (m.ControlMode.COAST,) * 2,
            duty=(0.0, 0.4, -0.4, 0.0, 0.0),
            effort=(0.0,) * 5,
        )
    )
    before = board.theta2.copy()
    link.sleep(0.3)
    drive = board.drive
    assert drive[1][0][0] == "forward" and drive[2][1][0] == "forward"  # B pulls to extend
    assert board.theta2[1] > before[1] + 0.1  # index flexes
    assert board.theta2[2] < before[2] - 0.1  # middle extends
    assert board.motor_current[0].tolist() == [0.0, 0.0]  # the thumb coasts: circuit open
    assert board.motor_current[1, 0] > 0.01


def test_deterministic_for_a_seed(firmware_elf: Path) -> None:
    def run(seed: int) -> np.ndarray:
        with EmulatedBoard(
            firmware_elf, realtime=False, plant="mujoco", seed=seed, exchange_period=1e-3
        ) as b:
            link = link_for(b)
            link.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=(0.6,) * 5))
            set_modes(link, m.ControlMode.POSITION)
            link.sleep(0.5)
            return b.plant.data.qpos.copy()

    a = run(3)
    assert np.array_equal(a, run(3))
    assert not np.array_equal(a, run(4))  # the encoders' noise is the seed's


def test_faults_on_the_mujoco_hand(board: EmulatedBoard) -> None:
    link = link_for(board)
    board.block_finger(1)  # jammed where it is
    set_modes(link, m.ControlMode.DUTY, mask=0b00010, duty=0.6)
    link.sleep(1.0)
    assert m.FaultBits.STALL in link.request(m.GetStatus()).faults[1]
    assert abs(board.theta2[1]) < 0.02
    board.unplug_encoder(2)
    link.sleep(0.02)
    assert m.FaultBits.ENCODER_RANGE in link.request(m.GetStatus()).faults[2]


def test_fingers_closing_on_an_object_press_on_it(firmware_elf: Path) -> None:
    plant = MujocoPlant(obj="ball", timestep=1e-3)
    with EmulatedBoard(firmware_elf, realtime=False, plant=plant, exchange_period=1e-3) as b:
        link = link_for(b)
        plant.hold_object(True)  # kept in place while the fingers close
        p0, _ = plant.object_pose()
        set_modes(link, m.ControlMode.DUTY, mask=0b11110, duty=0.5)
        link.sleep(1.5)
        forces = plant.contact_forces()
        assert forces[0] == 0.0  # the thumb coasts, out of reach
        assert (forces[1:] > 1.0).sum() >= 2  # fingers press on it
        assert b.theta2[1:].max() < 1.6  # stopped by the ball, short of full flexion
        p1, _ = plant.object_pose()
        assert np.linalg.norm(p1 - p0) < 2e-3


def _stretch(params: PlantParams, force_n: float) -> float:
    """The index's coupling stretch (m) under a settled tip load: how far the joints leave the
    rigid coupling (R1 θ1 = R2 θ2 = R3 θ3), which only the elastic coupling tendons allow."""
    plant = MujocoPlant(params=params, timestep=1e-3)
    plant.set_theta2(1, 0.6)
    plant.model.opt.gravity[:] = 0.0
    brake = np.zeros((5, 2, 4))
    brake[:, :, 1:] = 1.0  # IN1, IN2 and STBY high: short brake
    plant.set_tip_force(1, (0.0, -force_n), ramp_s=0.05)
    for _ in range(600):
        plant.step(1e-3, brake.reshape(-1))
    q = plant.theta[1] * plant.R[1]  # each joint's tendon displacement
    return float(np.abs(np.diff(q)).sum())


def test_the_hidden_modulus_is_the_twins_tendon_stiffness() -> None:
    """The emulated truth's coupling modulus builds the twin's elastic tendons: at half the
    geometry's modulus, the same tip load stretches them twice as far."""
    stiff = _stretch(PlantParams(coupling_modulus_pa=200e9, encoder=QUIET.encoder), 10.0)
    soft = _stretch(PlantParams(coupling_modulus_pa=100e9, encoder=QUIET.encoder), 10.0)
    assert stiff > 1e-7
    assert soft / stiff == pytest.approx(2.0, rel=0.15)


def test_a_tip_force_ramps_and_the_motors_are_the_plants() -> None:
    plant = MujocoPlant(params=PlantParams(motor=PlantParams().motor), timestep=1e-3)
    plant.set_tip_force(2, (3.0, -4.0), ramp_s=0.1)
    for _ in range(50):
        plant.step(1e-3)
    np.testing.assert_allclose(plant.applied_force[2], (1.5, -2.0), atol=0.05)
    for _ in range(60):
        plant.step(1e-3)
    np.testing.assert_allclose(plant.applied_force[2], (3.0, -4.0), atol=1e-9)
    assert plant.applied_force[[0, 1, 3, 4]].max() == 0.0
    with pytest.raises(Exception, match="ramp_s"):
        plant.set_tip_force(2, (0.0, 0.0), ramp_s=-1.0)
    from utrf.hil.rig import RIG_ACTUATOR as BENCH_ACTUATOR

    bench = MujocoPlant(params=PlantParams(motor=BENCH_ACTUATOR), timestep=1e-3)
    aid = bench.model.actuator("index_motor_a").id
    assert bench.model.actuator_forcerange[aid, 1] == pytest.approx(BENCH_ACTUATOR.stall_force_n)
