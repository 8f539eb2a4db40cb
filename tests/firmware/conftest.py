"""Fixtures of the firmware suite: the host build of the firmware core, one simulated board."""

from __future__ import annotations

import ctypes
from collections.abc import Iterator

import pytest
from fwsim import Sim, build_library, load_library


@pytest.fixture(scope="session")
def fwlib() -> ctypes.CDLL:
    return load_library(build_library())


@pytest.fixture
def sim(fwlib: ctypes.CDLL) -> Iterator[Sim]:
    """A freshly powered board with a blank EEPROM, encoders at the straight pose."""
    s = Sim(fwlib)
    eeprom = s.eeprom()
    ctypes.memset(eeprom, 0xFF, len(eeprom))
    fwlib.fw_set_eeprom_busy_polls(0)
    fwlib.fw_set_eeprom_stuck(-1)
    s.power_on()
    yield s
    # No test may leave the firmware having broken its own locking or transmit rules.
    assert s.status().lock_errors == 0
