"""What the bring-up's tests share (beside conftest.py's fixtures)."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand

#: ``built(*faults)``: a driven board built with those faults, and a Hand on it
Built = Callable[..., AbstractContextManager[tuple[EmulatedBoard, Hand]]]
