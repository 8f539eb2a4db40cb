"""The emulated board: the real firmware ELF on simavr (ATmega2560, 16 MHz), wired to a plant
model of the five fingers, with fault injection; served on a pty and a TCP port.

``EmulatedBoard`` is the entry point; ``README.md`` in this directory documents the API, the
time modes and the plant's assumptions.
"""

from utrf.emulator.board import (
    DEFAULT_ELF,
    VECTORS,
    CycleProfile,
    EmulatedBoard,
    EmulatorError,
    HarnessError,
    PinState,
    SimSerial,
    check_elf,
)
from utrf.emulator.build_faults import BuildFaults, FingerBuild
from utrf.emulator.plant_params import EncoderParams, MotorParams, PlantError, PlantParams
from utrf.emulator.process import BoardProcess

__all__ = [
    "DEFAULT_ELF",
    "VECTORS",
    "BoardProcess",
    "BuildFaults",
    "CycleProfile",
    "EmulatedBoard",
    "EmulatorError",
    "EncoderParams",
    "FingerBuild",
    "HarnessError",
    "MotorParams",
    "PinState",
    "PlantError",
    "PlantParams",
    "SimSerial",
    "check_elf",
]
