"""``utrf bringup``: a new hand's first power-on (docs/bringup.md)."""

from utrf.bringup.findings import Finding, FingerConfig
from utrf.bringup.procedure import BringupResult, FingerResult, bringup
from utrf.bringup.pulses import Bounds

__all__ = ["Bounds", "BringupResult", "Finding", "FingerConfig", "FingerResult", "bringup"]
