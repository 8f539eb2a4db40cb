"""Tip loads in the emulated plant (the MuJoCo hand): ramps, hits, bad loads refused; and,
with the real firmware holding Joint 2, the motor effort a payload needs and the recovery after
a hammer hit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from utrf.emulator import EmulatedBoard, EmulatorError, PlantError, PlantParams
from utrf.emulator.mujoco_plant import MujocoPlant
from utrf.hand import Hand
from utrf.models import calibration, statics

DT = 1e-3  # the board's exchange period with the MuJoCo plant
INDEX = 1


def test_force_ramps_in_and_pulses_carry_their_impulse() -> None:
    plant = MujocoPlant(timestep=DT)
    plant.set_tip_force(INDEX, (0.0, -10.0), ramp_s=0.1)
    seen = []
    for _ in range(round(0.2 / DT)):
        plant.step(DT)
        seen.append(plant.applied_force[INDEX, 1])
    seen = np.array(seen)
    t = DT * np.arange(1, seen.size + 1)
    np.testing.assert_allclose(seen, -10.0 * np.minimum(t / 0.1, 1.0), atol=1e-9)
    plant.set_tip_force(INDEX, (0.0, 0.0))
    # A hit is a force pulse on the last link at the tip: step it one MuJoCo step at a time
    # and add up the force applied in each.
    h = plant.max_step_s
    plant.set_timestep(h)
    link3 = plant.model.body(f"{plant.names[INDEX]}_link3").id
    plant.hit(INDEX, (0.05, 0.2), duration_s=3.1e-3)  # not a whole number of steps
    assert plant.native.pulses() == 1
    total = np.zeros(3)
    for _ in range(20):
        plant.step(h)
        total += plant.data.xfrc_applied[link3, :3] * h
    _, rot = plant.frames[INDEX]
    np.testing.assert_allclose(rot.T @ total, (0.05, 0.2, 0.0), rtol=1e-9, atol=1e-12)
    assert plant.native.pulses() == 0
    assert not plant.data.xfrc_applied.any()  # the pulse is over, nothing lingers


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda p: p.set_tip_force(1, (math.nan, 0.0)), "tip force"),
        (lambda p: p.set_tip_force(1, (1.0,)), "tip force"),
        (lambda p: p.set_tip_force(1, (0.0, -1.0), ramp_s=-1), "ramp_s"),
        (lambda p: p.set_tip_force(7, (0.0, -1.0)), "finger"),
        (lambda p: p.hit(1, (0.0, 1.0), duration_s=0), "duration"),
        (lambda p: p.hit(1, "hard"), "impulse"),
    ],
)
def test_bad_loads_are_refused_by_name(call, needle: str) -> None:
    with pytest.raises(PlantError, match=needle):
        call(MujocoPlant(timestep=DT))


def test_params_refuse_a_bad_modulus() -> None:
    with pytest.raises(PlantError, match="coupling_modulus_pa"):
        PlantParams(coupling_modulus_pa=-1.0)


# -- with the real firmware -------------------------------------------------------------------
@pytest.fixture
def held(firmware_elf: Path):
    with (
        EmulatedBoard(firmware_elf, realtime=False, seed=5) as board,
        Hand.emulated(board) as hand,
    ):
        hand.move({INDEX: 0.0}, duration=0.3)
        yield board, hand


def test_holding_a_payload_takes_the_pull_the_statics_predict(held) -> None:
    board, hand = held
    with pytest.raises(EmulatorError, match="mass"):
        board.hang_payload(INDEX, -0.1)
    mass = 0.12  # within the hand's 100 N motors
    board.hang_payload(INDEX, mass, ramp_s=0.2)
    hand.clock.sleep(2.5)
    pull, th2 = [], []
    for _ in range(100):  # average over the hold's dither between encoder counts
        hand.clock.sleep(0.005)
        t1, t4 = board.tendon_tension[INDEX]
        pull.append(t1 - t4)
        th2.append(board.theta2[INDEX])
    g = board.plant.geometries[INDEX]
    q = calibration.hold_q(g, np.array([np.mean(th2)]), np.array([mass]))
    res = statics.solve(g, float(q[0]), statics.Load(payload_kg=mass))
    n1 = float(res.net_tensions_n[0])
    assert n1 > 40  # a real load on the motor
    assert np.mean(pull) == pytest.approx(n1, rel=0.03)
    # ... which the flexor's motor supplies: force K i, less its friction.
    motor = board.plant.params.motor
    i_a = board.motor_current[INDEX, 0]
    assert motor.force_constant_n_a * i_a == pytest.approx(board.tendon_tension[INDEX, 0], abs=8)
    assert not hand.state()[INDEX].faults


def test_a_hammer_hit_moves_the_finger_and_the_loop_recovers(held) -> None:
    board, hand = held
    hand.clock.sleep(0.5)
    before = board.theta2[INDEX]
    board.hit_tip(INDEX, (0.0, -0.15), duration_s=5e-3)  # a downward blow, 30 N for 5 ms
    trace = []
    t0 = board.sim_time
    while board.sim_time - t0 < 1.5:
        hand.clock.sleep(0.002)
        trace.append((board.sim_time - t0, board.theta2[INDEX]))
    t, th = np.array(trace).T
    dev = th - before
    assert dev.min() < -0.02  # knocked down by more than a degree
    settled = np.flatnonzero(np.abs(dev) > 0.012)
    assert t[settled[-1]] < 1.0  # back within 0.7 deg (under 2 ADC counts) within a second
    assert not hand.state()[INDEX].faults
