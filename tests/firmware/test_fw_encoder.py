"""The AS5600 analog reading as the firmware maps it: each ADC code to the Joint-2 angle at
the centre of the inputs the datasheet's ideal converter gives that code, so a reading is
unbiased (``firmware/src/core/encoder.h``)."""

from __future__ import annotations

import math

import numpy as np
from fwsim import BU, Sim, adc_for_angle, m

COUNT_RAD = 2 * math.pi / (0.8 * 1024)  # one ADC count of Joint-2 angle: 7.67 mrad


def ideal_adc(x: float) -> int:
    """The ATmega2560 datasheet's ideal converter ("ADC Accuracy Definitions": the first
    transition at 0.5 LSB, the last 1.5 LSB below Vref), x the input in LSB."""
    return min(max(math.floor(x + 0.5), 0), 1023)


def test_a_reading_stands_for_the_centre_of_its_count(sim: Sim) -> None:
    """Sweeping the true angle through 40 counts in steps of 1/50 count: each reading is
    within half a count (and a BU of rounding) of the truth, and the error averages to
    nothing. A map to the bottom of each count would read half a count (3.8 mrad) low."""
    truth = np.arange(-20 * COUNT_RAD, 20 * COUNT_RAD, COUNT_RAD / 50)
    read = []
    for theta in truth:
        sim.lib.fw_set_adc(0, ideal_adc(adc_for_angle(theta)))
        sim.run(2)  # a tick judges the ADC round the one before started
        read.append(sim.finger(0).theta_rad)
    err = np.array(read) - truth
    assert sim.finger(0).faults == 0
    assert np.abs(err).max() <= COUNT_RAD / 2 + BU
    assert abs(err.mean()) < 0.01 * COUNT_RAD
    # codes map to angles a count apart: 40 BU exactly
    assert set(np.round(np.diff(np.unique(read)) / BU).astype(int)) == {40}


def _judged_run(sim: Sim, samples: np.ndarray, general: bool) -> list[tuple[int, ...]]:
    """Each tick's finger states over a sequence of ADC samples (ticks x fingers), every
    reading through the tick's fast path (judged by the sampler) or its general one."""
    sim.power_on()
    sim.lib.fw_encoder_general_path(1 if general else 0)
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    seen = []
    for k, row in enumerate(samples):
        for f, adc in enumerate(row):
            sim.lib.fw_set_adc(f, int(adc))
        if k % 40 == 20:  # the faults cleared, and two fingers back in POSITION when they can
            sim.send(m.ClearFaults(mask=0b11111))
            sim.loop(2)
            if k % 80 == 20:
                sim.send(
                    m.SetMode(mask=0b110, mode=(0, 2, 2, 0, 0), duty=(0,) * 5, effort=(0,) * 5)
                )
                sim.loop(2)
        sim.tick(1)
        sim.loop(1)
        for f in range(5):
            fg = sim.finger(f)
            seen.append((k, f, fg.theta, fg.faults, fg.mode, fg.has_theta, fg.target))
    sim.lib.fw_encoder_general_path(0)
    return seen


def test_the_encoders_fast_and_general_paths_judge_alike(sim: Sim) -> None:
    """The tick takes a reading the sampler found clean on its fast path (the jump rule
    only) and judges any other itself (Finger::judge_reading(): band, limits and jump, with
    encoder::judge(), the sampler's own rule). Fed the same readings, every reading through
    either path: the same angles, faults and modes, tick by tick. The readings wander, jump,
    leave the band and pass the joint limits."""
    rng = np.random.default_rng(23)
    ticks = 400
    straight = adc_for_angle(0.0)
    walk = np.cumsum(rng.normal(0.0, 2.0, size=(ticks, 5)), axis=0) + straight
    events = rng.random((ticks, 5))
    samples = np.where(events < 0.02, rng.choice([0, 40, 1000, 1023], size=(ticks, 5)), walk)
    samples = np.where((events > 0.97), walk + rng.choice([-60, 60], size=(ticks, 5)), samples)
    samples[150:170, 3] = adc_for_angle(2.5)  # far beyond finger 3's flexion limit
    samples = np.clip(np.round(samples), 0, 1023)
    fast = _judged_run(sim, samples, general=False)
    general = _judged_run(sim, samples, general=True)
    assert general == fast
    faults = {s[3] for s in fast}
    # the run met every encoder rule (so the comparison covers them)
    for bit in (m.FaultBits.ENCODER_RANGE, m.FaultBits.ENCODER_JUMP, m.FaultBits.JOINT_LIMIT):
        assert any(f & bit for f in faults), bit
