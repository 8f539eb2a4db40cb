"""The board's settings the dashboard edits (gains, limits, motion), each field with its range
and unit from the protocol (``protocol/spec.toml`` through the generated messages): a value
outside is refused here, with a message naming it, and nothing is sent."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from utrf.protocol import messages as m
from utrf.protocol.codec import Field, Message

#: group -> the set_ message whose fields (all but ``finger``) are the settings
GROUPS: dict[str, type[Message]] = {
    "gains": m.SetGains,
    "limits": m.SetLimits,
    "motion": m.SetMotion,
}


@dataclass(frozen=True)
class Setting:
    name: str
    lo: float
    hi: float
    unit: str

    def describe(self) -> str:
        unit = "" if self.unit in ("", "1") else f" {self.unit}"
        return f"{self.name} in [{self.lo:g}, {self.hi:g}]{unit}"


def _setting(f: Field) -> Setting:
    lo, hi = f.si_bounds()
    return Setting(f.name, float(lo), float(hi), f.unit)


def settings(group: str) -> list[Setting]:
    """The editable fields of ``group`` (``gains``, ``limits``, ``motion``) in wire order."""
    if group not in GROUPS:
        raise KeyError(f"no settings group {group!r}; groups are {list(GROUPS)}")
    return [_setting(f) for f in GROUPS[group].FIELDS if f.name != "finger"]


class SettingsError(ValueError):
    """Values outside the protocol's ranges: every one is named; nothing was sent."""

    def __init__(self, group: str, problems: list[str]) -> None:
        super().__init__(f"{group}: " + "; ".join(problems) + " (nothing was sent)")
        self.problems = problems


def check(group: str, values: Mapping[str, object]) -> dict[str, float]:
    """``values`` as floats if every one is a number within its field's range; else
    SettingsError naming each that is not."""
    known = {s.name: s for s in settings(group)}
    problems: list[str] = []
    out: dict[str, float] = {}
    for name, value in values.items():
        s = known.get(name)
        if s is None:
            problems.append(f"{name} is not a {group} field ({', '.join(known)})")
            continue
        try:
            v = float(value)  # type: ignore[arg-type]  # checked by the except
        except (TypeError, ValueError):
            problems.append(f"{name} = {value!r} is not a number")
            continue
        if not math.isfinite(v) or not s.lo <= v <= s.hi:
            problems.append(f"{name} = {v:g} is outside its range [{s.lo:g}, {s.hi:g}]")
            continue
        out[name] = v
    if group == "limits" and not problems:
        lo, hi = out.get("theta2_min"), out.get("theta2_max")
        if lo is not None and hi is not None and not lo < hi:
            problems.append(f"theta2_min {lo:g} must be below theta2_max {hi:g}")
    if problems:
        raise SettingsError(group, problems)
    return out
