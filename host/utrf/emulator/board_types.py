"""What the emulated board's API speaks in: its error, the ATmega2560's interrupt vectors,
reset flags and EEPROM size, and the value types it returns (cycle profiles, pin states)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

EEPROM_SIZE = 4096

# MCUSR bits, and the order in which the protocol's ResetCause reports them.
RESET_FLAGS = {
    "power_on": 0x01,
    "reset_pin": 0x02,
    "brown_out": 0x04,
    "watchdog": 0x08,
    "jtag": 0x10,
}

# Interrupt vectors of the ATmega2560 (datasheet Table 14-1, numbering from 0 = RESET).
VECTORS = {
    "INT4": 5,
    "INT5": 6,
    "WDT": 12,
    "TIMER2_COMPA": 13,
    "TIMER2_COMPB": 14,
    "TIMER2_OVF": 15,
    "TIMER1_COMPA": 17,
    "TIMER1_OVF": 20,
    "TIMER0_COMPA": 21,
    "TIMER0_OVF": 23,
    "USART0_RX": 25,
    "USART0_UDRE": 26,
    "USART0_TX": 27,
    "ADC": 29,
    "EE_READY": 30,
}


class EmulatorError(RuntimeError):
    """A request the emulated board cannot honour; the message says what to do."""


@dataclass(frozen=True)
class CycleProfile:
    """Cycles spent in an interrupt handler or a function, per call.

    ``mean``/``worst``/``best`` leave out interrupts that nest inside; ``*_incl`` count them.
    ``period`` is the mean interval between entries; ``load`` and ``worst_load`` divide by it
    (the fraction of the CPU the code takes). For an interrupt, ``latency`` and
    ``worst_latency`` count the cycles from its flag being raised to its handler's entry (long
    when the firmware masks it)."""

    calls: int
    mean: float
    worst: int
    best: int
    mean_incl: float
    worst_incl: int
    period: float
    latency: float = math.nan  # interrupt: mean cycles from its flag to its entry
    worst_latency: int = 0

    @property
    def load(self) -> float:
        return self.mean / self.period if self.period else math.nan

    @property
    def worst_load(self) -> float:
        return self.worst / self.period if self.period else math.nan

    @classmethod
    def from_native(cls, p: dict[str, int]) -> CycleProfile:
        n = p["count"]
        return cls(
            calls=n,
            mean=p["total"] / n if n else math.nan,
            worst=p["worst"],
            best=p["best"],
            mean_incl=p["total_incl"] / n if n else math.nan,
            worst_incl=p["worst_incl"],
            period=p["period_sum"] / p["intervals"] if p["intervals"] else math.nan,
            latency=p["latency_sum"] / n if n else math.nan,
            worst_latency=p["latency_worst"],
        )


@dataclass(frozen=True)
class PinState:
    """What the TB6612FNGs see, per finger (axis 0) and channel (axis 1: motor A, motor B)."""

    duty: np.ndarray  # PWM duty at the driver's PWM input, 0..1
    in1: np.ndarray  # bool
    in2: np.ndarray  # bool
    stby: np.ndarray  # bool, per finger

    @classmethod
    def from_block(cls, block: np.ndarray) -> PinState:
        return cls(
            duty=block[..., 0].copy(),
            in1=block[..., 1] > 0.5,
            in2=block[..., 2] > 0.5,
            stby=block[:, 0, 3] > 0.5,
        )
