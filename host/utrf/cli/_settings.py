"""The board's settings as the command line shows them: the groups (gains, limits, motion,
safety, hardware), their fields and ranges from the protocol (``protocol/spec.toml``), the
units people read (degrees for angles), and every value checked against the protocol's range
before anything is sent. The API and the backup file stay SI.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from utrf.hand import Hand
from utrf.protocol import messages as m
from utrf.protocol.codec import Field, Message

Value = float | int | IntEnum


class SettingError(ValueError):
    """A setting the protocol would refuse: names the field and its range."""


@dataclass(frozen=True)
class Group:
    name: str
    message: type[Message]  # the set_* message: its fields and ranges
    per_finger: bool
    what: str

    @property
    def fields(self) -> tuple[Field, ...]:
        return tuple(f for f in self.message.FIELDS if f.name != "finger")

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise SettingError(
            f"{self.name} has no field {name!r}; its fields are {[f.name for f in self.fields]}"
        )


GROUPS: dict[str, Group] = {
    g.name: g
    for g in (
        Group("gains", m.SetGains, True, "a finger's controller gains"),
        Group("limits", m.SetLimits, True, "a finger's supervision limits"),
        Group("motion", m.SetMotion, True, "a finger's move limits and feedforward"),
        Group("safety", m.SetSafety, False, "the board's host-silence rule"),
        Group("hardware", m.SetFingerConfig, True, "a finger's actuation and encoder"),
    )
}


def person_unit(field: Field) -> tuple[str, float]:
    """The unit people read and the factor from SI: angles in degrees (rad/s -> deg/s,
    1/rad -> 1/deg); duty fractions have none."""
    unit = field.unit
    if "rad" not in unit:
        return ("" if unit == "1" else unit), 1.0
    factor = 180.0 / math.pi if unit.startswith("rad") else math.pi / 180.0
    return unit.replace("rad", "deg"), factor


def show(field: Field, value: Value, *, with_unit: bool = True) -> str:
    """A value as people read it, with its unit (or without: a table's column says it)."""
    if field.enum is not None:
        return field.enum(int(value)).name.lower()
    if field.unit == "" and field.scale is None and field.type != "f32":
        return str(int(value))
    unit, factor = person_unit(field)
    return f"{float(value) * factor:.6g}" + (f" {unit}" if unit and with_unit else "")


def _range(field: Field) -> str:
    lo, hi = field.si_bounds()
    unit, factor = person_unit(field)
    text = f"{lo * factor:.6g} .. {hi * factor:.6g}" + (f" {unit}" if unit else "")
    if factor != 1.0:
        text += f" ({lo:.6g} .. {hi:.6g} {field.unit})"
    return text


def check(group: Group, field: Field, value: Any) -> Value:
    """``value`` (SI, or an enum's name) as the protocol takes it; SettingError naming the
    field and its range otherwise (the codec's own check: one home for the ranges)."""
    where = f"{group.name}.{field.name}"
    if field.enum is not None:
        if isinstance(value, str):
            try:
                return field.enum[value.upper()]
            except KeyError:
                names = [e.name.lower() for e in field.enum]
                raise SettingError(f"{where} must be one of {names}, got {value!r}") from None
        names = [e.name.lower() for e in field.enum]
        raise SettingError(f"{where} must be one of {names}, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SettingError(f"{where} must be a number, got {value!r}")
    try:
        field.to_raw(value, where)
    except ValueError:
        unit, factor = person_unit(field)
        shown = f"{value * factor:.6g}" + (f" {unit}" if unit else "")
        raise SettingError(f"{where} = {shown} is outside its range {_range(field)}") from None
    if field.type != "f32" and field.scale is None:
        if value != int(value):
            raise SettingError(f"{where} must be a whole number, got {value!r}")
        return int(value)
    return float(value)


def parse_assignment(group: Group, text: str) -> tuple[str, Value]:
    """``NAME=VALUE`` in the unit people read (degrees for angles) -> (name, SI value)."""
    name, sep, raw = text.partition("=")
    if not sep or not name or not raw:
        raise SettingError(f"{group.name}: expected NAME=VALUE, got {text!r}")
    field = group.field(name.strip())
    raw = raw.strip()
    if field.enum is not None:
        return field.name, check(group, field, raw)
    try:
        number = float(raw)
    except ValueError:
        raise SettingError(f"{group.name}.{field.name} must be a number, got {raw!r}") from None
    _, factor = person_unit(field)
    return field.name, check(group, field, number / factor if factor != 1.0 else number)


def read(hand: Hand, group: Group, finger: int | None) -> dict[str, Value]:
    """The group's values now in use on the board (SI; enums as enums)."""
    msg: Message
    if group.name == "gains":
        msg = hand.gains(finger if finger is not None else 0)
    elif group.name == "limits":
        msg = hand.limits(finger if finger is not None else 0)
    elif group.name == "motion":
        msg = hand.motion(finger if finger is not None else 0)
    elif group.name == "hardware":
        msg = hand.finger_config(finger if finger is not None else 0)
    else:
        msg = hand.safety()
    return {f.name: getattr(msg, f.name) for f in group.fields}


def write(hand: Hand, group: Group, finger: int | None, changes: Mapping[str, Value]) -> None:
    """Set the fields named (checked already) through the Hand's setter."""
    if not changes:
        return
    f = finger if finger is not None else 0
    if group.name == "gains":
        hand.set_gains(f, **{k: float(v) for k, v in changes.items()})
    elif group.name == "limits":
        hand.set_limits(f, **{k: float(v) for k, v in changes.items()})
    elif group.name == "motion":
        hand.set_motion(f, **{k: float(v) for k, v in changes.items()})
    elif group.name == "hardware":
        hand.set_finger_config(f, **dict(changes))
    else:
        timeout, action = changes.get("heartbeat_timeout"), changes.get("safe_action")
        hand.set_safety(
            heartbeat_timeout=None if timeout is None else float(timeout),
            safe_action=None if action is None else m.SafeAction(int(action)),
        )
