"""The twin built wrong (utrf.emulator.build_faults), on the MuJoCo plant alone (no MCU): each
fault is where the physical fault is, and words that do not describe one are refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_emu_plant import QUIET, pins_for, run

from utrf.emulator import BuildFaults, PlantError
from utrf.emulator.mujoco_plant import MujocoPlant

FLEX = (0.4, 1, 0, 1)  # motor A: duty 0.4 forward (pull), driver on


def _plant(*faults: str) -> MujocoPlant:
    plant = MujocoPlant(params=QUIET)
    BuildFaults.parse(list(faults)).apply(plant)
    return plant


def test_the_model_build_flexes_the_driven_finger() -> None:
    plant = _plant()
    run(plant, 0.2, pins_for(f1a=FLEX))
    assert plant.theta2[1] > 0.1 and plant.theta2[2] < 0  # the others sag under gravity


def test_swapped_cables_move_the_other_finger() -> None:
    plant = _plant("swap-cables:1,2")
    run(plant, 0.2, pins_for(f1a=FLEX))  # finger 1's driver
    assert plant.theta2[2] > 0.1 and plant.theta2[1] < 0


def test_swapped_leads_push_instead_of_pulling() -> None:
    plant = _plant("swap-leads:1")
    run(plant, 0.2, pins_for(f1a=FLEX))
    assert plant.theta2[1] < -0.1  # motor A lets the finger go instead of pulling it


def test_an_unpowered_finger_draws_no_current() -> None:
    plant = _plant("unpowered:1")
    run(plant, 0.1, pins_for(f1a=FLEX))
    assert plant.current[1, 0] == 0.0 and abs(plant.theta2[1]) < 0.05


def test_a_weaker_motor_stalls_at_less_force() -> None:
    model, weak = _plant(), _plant("weak-motor:1=0.5")
    for p in (model, weak):
        p.block(1)
        run(p, 0.05, pins_for(f1a=FLEX))
    assert weak.current[1, 0] == pytest.approx(0.5 * model.current[1, 0], rel=0.02)


def test_the_encoder_faults_are_in_its_reading() -> None:
    model = _plant()
    plant = _plant("invert-magnet:1", "magnet-offset:3=0.5", "swap-encoders:2,4", "unplugged:0")
    for p in (model, plant):
        p.set_theta2(1, 0.3)
        p.set_theta2(4, 0.6)
    v0, v = model.encoder_volts(), plant.encoder_volts()
    per_rad = 0.8 * 5.0 / (2 * math.pi)
    assert v[0] == 0.0  # unplugged
    assert v[1] - 2.5 == pytest.approx(-(v0[1] - 2.5), abs=2e-3)  # mirrored about mid-band
    assert v[3] - v0[3] == pytest.approx(0.5 * per_rad, abs=2e-3)  # turned by 0.5 rad
    assert v[2] == pytest.approx(v0[4], abs=2e-3) and v[4] == pytest.approx(v0[2], abs=2e-3)


def test_a_narrower_range_stops_flexion_early() -> None:
    plant = _plant("narrow-range:1=1.0")
    run(plant, 2.0, pins_for(f1a=FLEX))
    assert 0.9 < plant.theta2[1] < 1.05


def test_random_builds_are_seeded_and_have_their_faults() -> None:
    a, b = BuildFaults.random(3, faults=3), BuildFaults.random(3, faults=3)
    assert a == b and a != BuildFaults.random(4, faults=3)
    assert 2 <= len(a.faults()) <= 3
    scales = np.array([[f.force_scale, f.speed_scale] for f in a.fingers])
    assert np.all((scales >= 0.7) & (scales <= 1.3))


@pytest.mark.parametrize(
    ("word", "needle"),
    [
        ("swap-leads", "KIND:FINGER"),
        ("nonsense:1", "kinds:"),
        ("slack:1", "takes a value"),
        ("invert-magnet:1=2", "takes no value"),
        ("swap-cables:1", "names two fingers"),
        ("slack:pinky=0.001", "is not a finger"),
        ("slack:1=lots", "is not a number"),
        ("slack:1=0.5", "slack must lie"),
    ],
)
def test_a_bad_word_is_refused_naming_it(word: str, needle: str) -> None:
    with pytest.raises(PlantError, match=needle):
        BuildFaults.parse([word])
