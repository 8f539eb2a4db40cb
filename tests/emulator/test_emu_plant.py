"""The MuJoCo plant on its own, without the firmware: the TB6612FNG truth table
(``harness/drive.c``) and the DC motor model (``harness/mjplant.c``) that turn the board's
pins into actuator forces, the AS5600's transfer, quantisation, noise and faults, determinism
for a seed, and the parameter checks."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from utrf.emulator.mujoco_plant import MujocoPlant
from utrf.emulator.plant_params import (
    BRAKE,
    COAST,
    FORWARD,
    REVERSE,
    EncoderParams,
    MotorParams,
    PlantError,
    PlantParams,
)
from utrf.models.geometry import HandGeometry

DT = 1e-3  # the board's exchange period with the MuJoCo plant
NO_GRAVITY = PlantParams(gravity_m_s2=(0.0, 0.0))
QUIET = PlantParams(encoder=EncoderParams(noise_v=0.0))


def pins_for(**channels: tuple[float, int, int, int]) -> np.ndarray:
    """Pin block with the named channels set, e.g. f1a=(duty, in1, in2, stby)."""
    block = np.zeros((5, 2, 4))
    for name, values in channels.items():
        block[int(name[1]), "ab".index(name[2])] = values
    return block


def run(plant: MujocoPlant, seconds: float, pins: np.ndarray) -> None:
    for _ in range(round(seconds / DT)):
        plant.step(DT, pins)


@pytest.fixture(scope="module")
def quiet() -> MujocoPlant:
    return MujocoPlant(params=QUIET, timestep=DT)


def test_tb6612_truth_table() -> None:
    plant = MujocoPlant(params=NO_GRAVITY, timestep=DT)
    plant.step(
        DT,
        pins_for(
            f1a=(0.5, 1, 0, 1),  # forward at half duty
            f1b=(0.5, 0, 1, 1),  # reverse
            f2a=(0.7, 1, 1, 1),  # short brake, whatever the PWM
            f2b=(0.7, 0, 0, 1),  # coast
            f3a=(0.9, 1, 0, 0),  # STBY low: off
        ),
    )
    assert plant.drive_mode[1].tolist() == [FORWARD, REVERSE]
    assert plant.drive_mode[2].tolist() == [BRAKE, COAST]
    assert plant.drive_mode[3, 0] == COAST
    np.testing.assert_allclose(plant.drive_duty[1], [0.5, -0.5])
    assert plant.drive_duty[2].tolist() == [0.0, 0.0]
    # the motors driven draw current, and each draws it the way its duty's sign says
    assert plant.current[1, 0] > 0.01 and plant.current[1, 1] < -0.01
    # coasting opens the circuit: no current at all
    assert plant.current[2, 1] == 0.0 and plant.current[3, 0] == 0.0


def test_blocked_finger_stalls_its_motor_at_the_duty_s_current() -> None:
    """The DC motor model: held still, the current settles at u V / R (the stall current at
    the duty), and the tendon then pulls with the motor's K i."""
    m = NO_GRAVITY.motor
    plant = MujocoPlant(params=NO_GRAVITY, timestep=DT)
    plant.set_theta2(1, 0.3)
    plant.block(1, 0.3)  # jammed at 0.3 rad
    run(plant, 0.3, pins_for(f1a=(0.8, 1, 0, 1)))
    assert plant.theta2[1] == pytest.approx(0.3, abs=0.02)
    assert plant.current[1, 0] == pytest.approx(0.8 * m.stall_current_a, rel=0.02)
    assert plant.tension[1, 0] == pytest.approx(0.8 * m.stall_force_n, rel=0.1)
    plant.unblock(1)
    run(plant, 0.1, pins_for(f1a=(0.8, 1, 0, 1)))
    assert plant.theta2[1] > 0.4  # free again, it flexes on


def test_a_free_motor_s_back_emf_cuts_its_current() -> None:
    """Running free, the motor's back-EMF K v takes most of the supply: far less current than
    stalled at the same duty."""
    m = NO_GRAVITY.motor
    plant = MujocoPlant(params=NO_GRAVITY, timestep=DT)
    run(plant, 0.05, pins_for(f2a=(0.8, 1, 0, 1)))
    assert plant.theta2[2] > 0.05
    assert 0.0 < plant.current[2, 0] < 0.8 * m.stall_current_a


def test_rotary_finger_one_motor_both_ways() -> None:
    fingers = list(HandGeometry.default().fingers)
    fingers[3] = dataclasses.replace(fingers[3], actuation="rotary")
    hand = HandGeometry(name="rotary ring", fingers=tuple(fingers))
    plant = MujocoPlant(hand, NO_GRAVITY, timestep=DT)
    run(plant, 0.2, pins_for(f3a=(0.6, 1, 0, 1), f3b=(0.6, 0, 1, 1)))  # B's pins are ignored
    up = plant.theta2[3]
    assert up > 0.2
    assert plant.drive_mode[3, 1] == COAST
    run(plant, 0.3, pins_for(f3a=(0.6, 0, 1, 1)))
    assert plant.theta2[3] < up - 0.2


class TestEncoder:
    def test_straight_finger_reads_mid_band(self, quiet: MujocoPlant) -> None:
        for f in range(5):
            quiet.set_theta2(f, 0.0)
        np.testing.assert_allclose(quiet.encoder_volts(), 2.5)

    def test_transfer_slope_and_quantisation(self, quiet: MujocoPlant) -> None:
        for theta2 in (-1.5, -0.3, 0.4, 1.6):
            quiet.set_theta2(0, theta2)
            turn = (math.pi + theta2) / (2 * math.pi)
            volts = 5.0 * (0.1 + 0.8 * math.floor(turn * 4096) / 4096)  # 12-bit steps
            assert quiet.encoder_volts()[0] == pytest.approx(volts, abs=1e-12)
        # the whole range stays inside the band without wrapping
        quiet.set_theta2(0, quiet.geometries[0].theta2_range_rad[0])
        low = quiet.encoder_volts()[0]
        quiet.set_theta2(0, quiet.geometries[0].theta2_range_rad[1])
        assert 0.5 < low < quiet.encoder_volts()[0] < 4.5
        quiet.set_theta2(0, 0.0)

    def test_invert_mirrors_the_reading(self, quiet: MujocoPlant) -> None:
        inverted = MujocoPlant(
            params=PlantParams(encoder=EncoderParams(noise_v=0.0, invert=True)), timestep=DT
        )
        for p in (quiet, inverted):
            p.set_theta2(1, 0.5)
        up, down = quiet.encoder_volts()[1] - 2.5, 2.5 - inverted.encoder_volts()[1]
        quiet.set_theta2(1, 0.0)
        assert up > 0.3 and up == pytest.approx(down, abs=2e-3)

    def test_noise_is_seeded(self) -> None:
        a, b, c = (MujocoPlant(seed=s, timestep=DT) for s in (7, 7, 8))
        sa = np.array([a.encoder_volts() for _ in range(2000)])
        sb = np.array([b.encoder_volts() for _ in range(2000)])
        sc = np.array([c.encoder_volts() for _ in range(2000)])
        assert np.array_equal(sa, sb)
        assert not np.array_equal(sa, sc)
        # 2 mV of Gaussian noise around the 2.5 V of the straight finger
        assert np.abs(sa.mean(axis=0) - 2.5).max() < 3e-4
        assert np.all((sa.std(axis=0) > 1.8e-3) & (sa.std(axis=0) < 2.2e-3))

    def test_slipped_magnet_shifts_the_reading(self, quiet: MujocoPlant) -> None:
        quiet.shift_encoder(1, 0.3)
        volts = quiet.encoder_volts()
        quiet.shift_encoder(1, 0.0)
        slope = 0.8 * 5.0 / (2 * math.pi)  # V per rad
        assert volts[1] - volts[0] == pytest.approx(0.3 * slope, abs=2e-3)
        assert quiet.theta2[1] == 0.0  # the joint did not move

    def test_unplugged_reads_the_given_voltage(self) -> None:
        plant = MujocoPlant(timestep=DT)
        plant.unplug_encoder(2)
        plant.unplug_encoder(3, volts=4.8)
        v = plant.encoder_volts()
        assert v[2] == 0.0 and v[3] == 4.8
        plant.plug_encoder(2)
        assert abs(plant.encoder_volts()[2] - 2.5) < 0.012


def test_deterministic_for_a_seed() -> None:
    """The same seed and pins give the same motion and the same encoder readings, bit for bit;
    another seed other readings."""
    pins = pins_for(f1a=(0.6, 1, 0, 1), f2b=(0.4, 1, 0, 1), f4a=(0.3, 1, 0, 1))

    def trace(seed: int) -> tuple[np.ndarray, np.ndarray]:
        plant = MujocoPlant(seed=seed, timestep=DT)
        volts = []
        for _ in range(200):
            volts.append(plant.encoder_volts())
            plant.step(DT, pins)
        return plant.data.qpos.copy(), np.array(volts)

    qa, va = trace(3)
    qb, vb = trace(3)
    assert np.array_equal(qa, qb) and np.array_equal(va, vb)
    assert not np.array_equal(va, trace(4)[1])


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda p: MotorParams(stall_force_n=-1.0), "stall_force_n"),
        (lambda p: MotorParams(stroke_m=(0.01, -0.01)), "stroke_m"),
        (lambda p: EncoderParams(band=(0.9, 0.1)), "band"),
        (lambda p: PlantParams(gravity_m_s2=(0.0,)), "gravity_m_s2"),
        (lambda p: p.set_theta2(0, 3.0), "outside its range"),
        (lambda p: p.block(5), "finger must be 0..4"),
        (lambda p: p.block(1, direction="sideways"), "direction"),
        (lambda p: p.unplug_encoder(0, volts=7.0), "[0, 5] V"),
        (lambda p: p.shift_encoder(0, math.inf), "encoder shift"),
    ],
)
def test_bad_input_is_refused_with_its_name(quiet: MujocoPlant, make, needle: str) -> None:
    with pytest.raises(PlantError, match=needle.replace("[", r"\[").replace("(", r"\(")):
        make(quiet)
