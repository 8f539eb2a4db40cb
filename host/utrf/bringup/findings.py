"""What a bring-up finds on a finger, in plain words with the likely cause and the fix, and the
configuration it proposes for it."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

#: the kinds of finding, each with the build mistake it usually is
KINDS = {
    "encoder-signal": "the encoder's reading is outside its band",
    "no-motion": "no encoder movement when the motor is driven",
    "leads-swapped": "both motors turn the wrong way (their leads swapped)",
    "lead-a-swapped": "motor A turns the wrong way (its leads swapped)",
    "lead-b-swapped": "motor B turns the wrong way (its leads swapped)",
    "encoder-inverted": "motor and encoder turn opposite ways",
    "cable-swap": "a cable on another finger's channel",
    "magnet-offset": "the encoder's zero is off the model's",
    "not-monotonic": "the reading is not monotonic over the travel",
    "narrow-range": "this build's joint range is narrower than the model's",
    "slack": "slack between Joint 1 and Joint 2",
    "slow-motor": "the motor is slower than the model's",
    "weak-motor": "the motor is weaker than the model's",
    "friction": "more friction than the model's",
}


@dataclass
class Finding:
    finger: str
    kind: str
    message: str  # what was seen, and the likely cause
    fix: str  # what the configuration does about it, or what the person must do
    fixable: bool
    data: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown finding kind {self.kind!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def __str__(self) -> str:
        how = "fixed by configuration" if self.fixable else "NOT fixable by configuration"
        return f"{self.finger}: {self.message} -> {self.fix} ({how})"


@dataclass
class FingerConfig:
    """What a bring-up sets on one finger (SI): ``set_finger_config``, ``set_limits``,
    ``set_gains`` and ``set_motion`` fields. None: left as it is."""

    finger_config: dict[str, Any] = field(default_factory=dict)
    limits: dict[str, float] = field(default_factory=dict)
    gains: dict[str, float] = field(default_factory=dict)
    motion: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FingerConfig:
        return cls(**d)


#: beyond these, a proposed value differs from the saved one
SAME_ANGLE_RAD = 0.03
SAME_GAIN = 0.3

#: per field, how far a proposal may be from the saved value and still be the same (absolute
#: for angles and duties; relative for the gains): the identification's spread between runs
_ABS = {
    "encoder_offset": SAME_ANGLE_RAD,
    "theta2_min": SAME_ANGLE_RAD,
    "theta2_max": SAME_ANGLE_RAD,
    "deadband_duty": 0.02,
}


def changes(proposed: FingerConfig, saved: dict[str, dict[str, Any]]) -> list[str]:
    """The fields a proposal changes, as ``group.field: saved -> proposed``."""
    out = []
    for group, values in asdict(proposed).items():
        for k, v in values.items():
            old = float(saved[group][k])
            if k in _ABS:
                diff = abs(math.remainder(old - float(v), 2 * math.pi)) > _ABS[k]
            elif k in ("encoder_invert", "motor_invert"):
                diff = int(old) != int(v)
            else:
                diff = abs(old - float(v)) > SAME_GAIN * max(abs(float(v)), 1e-3)
            if diff:
                out.append(f"{group}.{k}: {old:.4g} -> {float(v):.4g}")
    return out
