"""The plant model on its own: drive decoding, physics, encoder transfer, faults."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from utrf.emulator.plant import (
    BRAKE,
    COAST,
    FORWARD,
    REVERSE,
    EncoderParams,
    HandPlant,
    MotorParams,
    PlantError,
    PlantParams,
)
from utrf.models import kinematics
from utrf.models.geometry import FingerSpec, HandGeometry

DT = 250e-6


def pins_for(**channels: tuple[float, int, int, int]) -> np.ndarray:
    """Pin block with the named channels set, e.g. f1a=(duty, in1, in2, stby)."""
    block = np.zeros((5, 2, 4))
    for name, values in channels.items():
        block[int(name[1]), "ab".index(name[2])] = values
    return block


def run(plant: HandPlant, seconds: float, pins: np.ndarray) -> None:
    for _ in range(round(seconds / DT)):
        plant.step(DT, pins)


def test_tb6612_truth_table() -> None:
    plant = HandPlant()
    plant.decode_drive(
        pins_for(
            f0a=(0.5, 1, 0, 1),  # forward at half duty
            f0b=(0.5, 0, 1, 1),  # reverse
            f1a=(0.7, 1, 1, 1),  # short brake, whatever the PWM
            f1b=(0.7, 0, 0, 1),  # coast
            f2a=(0.9, 1, 0, 0),  # STBY low: off
        )
    )
    assert plant.drive_mode[0].tolist() == [FORWARD, REVERSE]
    assert plant.drive_mode[1].tolist() == [BRAKE, COAST]
    assert plant.drive_mode[2, 0] == COAST
    np.testing.assert_allclose(plant.drive_duty[0], [0.5, -0.5])
    assert plant.drive_duty[1].tolist() == [0.0, 0.0]


def test_driven_finger_flexes_with_coupled_joints() -> None:
    plant = HandPlant(params=PlantParams(gravity_m_s2=(0.0, 0.0)))
    run(plant, 0.15, pins_for(f1a=(0.6, 1, 0, 1), f1b=(0.0, 0, 0, 1)))
    theta = plant.theta[1]
    assert theta[1] > 0.2, "motor A pulling Tendon 1 must flex the finger"
    R = np.array(plant.geometries[1].guide_radii_m)
    # θ1 : θ2 : θ3 = 1/R1 : 1/R2 : 1/R3
    np.testing.assert_allclose(theta * R, theta[0] * R[0], rtol=1e-12)
    # the undriven fingers did not move (no gravity)
    assert np.abs(plant.theta2[[0, 2, 3, 4]]).max() < 1e-9


def test_extensor_opens_a_flexed_finger() -> None:
    plant = HandPlant(params=PlantParams(gravity_m_s2=(0.0, 0.0)))
    plant.set_theta2(2, 1.0)
    run(plant, 0.1, pins_for(f2b=(0.6, 1, 0, 1)))
    assert plant.theta2[2] < 0.8


def test_speed_follows_the_motor_constants() -> None:
    """Free flexion at full duty approaches the no-load speed less the load's share."""
    params = PlantParams(gravity_m_s2=(0.0, 0.0), joint_damping_n_m_s=0.0)
    plant = HandPlant(params=params)
    plant.set_theta2(1, -1.0)
    run(plant, 0.08, pins_for(f1a=(1.0, 1, 0, 1)))
    speed = plant.qd[1]
    v0 = params.motor.no_load_speed_m_s
    assert 0.5 * v0 < speed <= v0 * 1.001


def test_gravity_sags_a_coasting_finger_and_brake_resists() -> None:
    coast = HandPlant()
    brake = HandPlant()
    run(coast, 0.3, pins_for())
    run(brake, 0.3, pins_for(f3a=(0.0, 1, 1, 1), f3b=(0.0, 1, 1, 1)))
    # gravity is along −y, flexion toward +y: the finger falls toward extension
    assert coast.theta2[3] < -0.1
    assert coast.theta2[3] < brake.theta2[3] < 0.0
    # without gravity, nothing moves
    still = HandPlant(params=PlantParams(gravity_m_s2=(0.0, 0.0)))
    run(still, 0.3, pins_for())
    assert np.abs(still.theta2).max() < 1e-12


def test_energy_is_conserved_without_losses() -> None:
    """Slack tendons, no damping: the finger swings under gravity and keeps its energy."""
    motor = MotorParams(coulomb_friction_n=0.0, viscous_friction_n_s_m=0.0)
    params = PlantParams(motor=motor, joint_damping_n_m_s=0.0, tendon_damping_n_s_m=0.0)
    plant = HandPlant(params=params)
    plant.x[:] = -0.02  # both actuators let their tendons go slack
    start = sum(plant.energy())
    kinetic_max = 0.0
    for _ in range(200):  # 50 ms: falling, not yet at the joint limit
        plant.step(DT, pins_for())
        kinetic_max = max(kinetic_max, plant.energy()[0])
        assert np.all(plant.tension == 0.0)
    assert kinetic_max > 1e-3, "the finger must have picked up speed"
    assert abs(sum(plant.energy()) - start) < 0.01 * kinetic_max


def test_damping_only_takes_energy_away() -> None:
    plant = HandPlant()
    plant.x[:] = -0.02
    energies = []
    for _ in range(400):
        plant.step(DT, pins_for())
        energies.append(sum(plant.energy()))
    assert np.all(np.diff(energies) <= 1e-12)


def test_blocked_finger_stalls_its_motor() -> None:
    params = PlantParams(gravity_m_s2=(0.0, 0.0))
    plant = HandPlant(params=params)
    plant.block(0, 0.3)  # jammed at 0.3 rad
    plant.set_theta2(0, 0.3)
    run(plant, 0.2, pins_for(f0a=(0.8, 1, 0, 1)))
    assert plant.theta2[0] == pytest.approx(0.3)
    m = params.motor
    # stalled: full current at the duty, tension = stall force x duty (less friction)
    assert plant.current[0, 0] == pytest.approx(0.8 * m.stall_current_a, rel=1e-3)
    assert plant.tension[0, 0] == pytest.approx(
        0.8 * m.stall_force_n, abs=m.coulomb_friction_n + 0.5
    )
    plant.unblock(0)
    run(plant, 0.05, pins_for(f0a=(0.8, 1, 0, 1)))
    assert plant.theta2[0] > 0.35


def test_obstacle_blocks_flexion_only() -> None:
    plant = HandPlant(params=PlantParams(gravity_m_s2=(0.0, 0.0)))
    plant.block(4, 0.5, direction="flexion")
    run(plant, 0.3, pins_for(f4a=(0.8, 1, 0, 1)))
    assert plant.theta2[4] == pytest.approx(0.5)
    # Motor B was dragged along, and coasted on: it first takes up its tendon's slack.
    run(plant, 0.4, pins_for(f4b=(0.8, 1, 0, 1)))
    assert plant.theta2[4] < 0.3


def test_joint_limits_hold() -> None:
    plant = HandPlant(params=PlantParams(gravity_m_s2=(0.0, 0.0)))
    run(plant, 1.0, pins_for(f1a=(1.0, 1, 0, 1), f2b=(1.0, 1, 0, 1)))
    lo, hi = plant.geometries[1].theta1_range_rad
    assert plant.theta[1, 0] == pytest.approx(hi)
    assert plant.theta[2, 0] == pytest.approx(lo)


def test_rotary_finger_one_motor_both_ways() -> None:
    default = HandGeometry.default()
    fingers = list(default.fingers)
    fingers[3] = dataclasses.replace(fingers[3], actuation="rotary")
    hand = HandGeometry(name="rotary ring", fingers=tuple(fingers))
    plant = HandPlant(hand, PlantParams(gravity_m_s2=(0.0, 0.0)))
    run(plant, 0.1, pins_for(f3a=(0.6, 1, 0, 1), f3b=(0.6, 0, 1, 1)))  # B's pins are ignored
    up = plant.theta2[3]
    assert up > 0.2
    assert plant.drive_mode[3, 1] == COAST
    run(plant, 0.2, pins_for(f3a=(0.6, 0, 1, 1)))
    assert plant.theta2[3] < up - 0.2


def test_tip_is_the_models_kinematics() -> None:
    plant = HandPlant()
    plant.set_theta2(2, 0.7)
    expected = kinematics.tip_position(plant.geometries[2], 0.7 * plant.R[2, 1])
    np.testing.assert_allclose(plant.tip[2], expected)


def test_dynamics_use_the_models_geometry() -> None:
    """The plant's centres of mass, differentiated, give the same finger the models describe:
    with the COM at the link ends they are the joint positions of utrf.models.kinematics."""
    geom = HandGeometry.default().fingers[1].geometry
    ends = dataclasses.replace(geom, link_com_fraction=(1.0, 1.0, 1.0))
    hand = HandGeometry(name="ends", fingers=tuple(FingerSpec(f"f{i}", ends) for i in range(5)))
    plant = HandPlant(hand)
    q = 0.004
    phi = q * plant.c[1]
    com = plant._A[1] @ np.stack((np.cos(phi), np.sin(phi)), axis=-1)
    np.testing.assert_allclose(com, kinematics.joint_positions(ends, q)[1:], atol=1e-15)


class TestEncoder:
    def test_straight_finger_reads_mid_band(self) -> None:
        plant = HandPlant(params=PlantParams(encoder=EncoderParams(noise_v=0.0)))
        np.testing.assert_allclose(plant.encoder_volts(), 2.5)

    def test_transfer_slope_and_quantisation(self) -> None:
        enc = EncoderParams(noise_v=0.0)
        plant = HandPlant(params=PlantParams(encoder=enc))
        for theta2 in (-1.5, -0.3, 0.4, 1.6):
            plant.set_theta2(0, theta2)
            turn = (math.pi + theta2) / (2 * math.pi)
            volts = 5.0 * (0.1 + 0.8 * math.floor(turn * 4096) / 4096)  # 12-bit steps
            assert plant.encoder_volts()[0] == pytest.approx(volts, abs=1e-12)
        # the whole range stays inside the band without wrapping
        plant.set_theta2(0, plant.geometries[0].theta2_range_rad[0])
        low = plant.encoder_volts()[0]
        plant.set_theta2(0, plant.geometries[0].theta2_range_rad[1])
        assert 0.5 < low < plant.encoder_volts()[0] < 4.5

    def test_invert_mirrors_the_reading(self) -> None:
        plain = HandPlant(params=PlantParams(encoder=EncoderParams(noise_v=0.0)))
        inverted = HandPlant(params=PlantParams(encoder=EncoderParams(noise_v=0.0, invert=True)))
        for p in (plain, inverted):
            p.set_theta2(1, 0.5)
        up, down = plain.encoder_volts()[1] - 2.5, 2.5 - inverted.encoder_volts()[1]
        assert up > 0.3 and up == pytest.approx(down, abs=2e-3)

    def test_noise_is_seeded(self) -> None:
        a, b, c = HandPlant(seed=7), HandPlant(seed=7), HandPlant(seed=8)
        sa = np.array([a.encoder_volts() for _ in range(2000)])
        sb = np.array([b.encoder_volts() for _ in range(2000)])
        sc = np.array([c.encoder_volts() for _ in range(2000)])
        assert np.array_equal(sa, sb)
        assert not np.array_equal(sa, sc)
        # 2 mV of Gaussian noise around the 2.5 V of the straight finger
        assert np.abs(sa.mean(axis=0) - 2.5).max() < 3e-4
        assert np.all((sa.std(axis=0) > 1.8e-3) & (sa.std(axis=0) < 2.2e-3))

    def test_slipped_magnet_shifts_the_reading(self) -> None:
        plant = HandPlant(params=PlantParams(encoder=EncoderParams(noise_v=0.0)))
        plant.shift_encoder(1, 0.3)
        volts = plant.encoder_volts()
        slope = 0.8 * 5.0 / (2 * math.pi)  # V per rad
        assert volts[1] - volts[0] == pytest.approx(0.3 * slope, abs=2e-3)
        assert plant.theta2[1] == 0.0  # the joint did not move

    def test_unplugged_reads_the_given_voltage(self) -> None:
        plant = HandPlant()
        plant.unplug_encoder(2)
        plant.unplug_encoder(3, volts=4.8)
        v = plant.encoder_volts()
        assert v[2] == 0.0 and v[3] == 4.8
        plant.plug_encoder(2)
        assert abs(plant.encoder_volts()[2] - 2.5) < 0.012


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda: MotorParams(stall_force_n=-1.0), "stall_force_n"),
        (lambda: MotorParams(stroke_m=(0.01, -0.01)), "stroke_m"),
        (lambda: EncoderParams(band=(0.9, 0.1)), "band"),
        (lambda: PlantParams(tendon_damping_n_s_m=-2.0), "tendon_damping"),
        (lambda: HandPlant().set_theta2(0, 3.0), "outside its range"),
        (lambda: HandPlant().block(5), "finger must be 0..4"),
        (lambda: HandPlant().block(1, direction="sideways"), "direction"),
        (lambda: HandPlant().unplug_encoder(0, volts=7.0), "[0, 5] V"),
    ],
)
def test_bad_input_is_refused_with_its_name(make, needle: str) -> None:
    with pytest.raises(PlantError, match=needle.replace("[", r"\[").replace("(", r"\(")):
        make()
