"""The AS5600 analog reading as the firmware maps it: each ADC code to the Joint-2 angle at
the centre of the inputs the datasheet's ideal converter gives that code, so a reading is
unbiased (``firmware/src/core/encoder.h``)."""

from __future__ import annotations

import math

import numpy as np
from fwsim import BU, Sim, adc_for_angle

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
