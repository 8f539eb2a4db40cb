"""A campaign file (TOML), read and checked before anything runs.

    [campaign]
    name = "finger-designs"
    kind = "design"              # design | grasp | function
    seed = 0

    [sampler]
    method = "lhs"               # grid | random | lhs | optuna
    samples = 100000             # random, lhs; optuna: trials
    cross = ["firmware"]         # every sampled row once with each of these values (A/B)

    [parameters]
    link1_m = { min = 0.05, max = 0.09 }          # a range (grid: add steps = N)
    radius1_m = [0.008, 0.010, 0.012]             # a list of values
    payload_kg = 1.0                              # one value

    [objectives]                 # the Pareto front's (and optuna's) objectives
    workspace_area_m2 = "max"

Every error is a :class:`CampaignError` naming the file and the line (an unknown parameter, a
range outside what the kind's model or the protocol accepts, a missing firmware). What each
kind accepts is the kind's business (``utrf.campaign.kinds``); this module reads the shapes.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

KINDS = ("design", "grasp", "function")
METHODS = ("grid", "random", "lhs", "optuna")
SECTIONS = {"campaign", "sampler", "parameters", "objectives", "firmware", "options"}


class CampaignError(ValueError):
    """A campaign that cannot run; the message names the file, the line and what is wrong."""


@dataclass(frozen=True)
class Range:
    """A parameter's interval; ``steps`` for a grid; ``integer`` draws whole numbers."""

    low: float
    high: float
    steps: int | None = None
    log: bool = False
    integer: bool = False


@dataclass(frozen=True)
class Param:
    """One parameter: a list of values (one value is a list of one) or a range."""

    name: str
    line: int
    values: tuple[Any, ...] | None = None
    range: Range | None = None

    @property
    def fixed(self) -> bool:
        return self.values is not None and len(self.values) == 1


@dataclass(frozen=True)
class Campaign:
    """A checked campaign file. ``where(key)`` says where a key was written."""

    source: str
    text: str
    name: str
    kind: str
    seed: int
    method: str
    samples: int
    chunk: int
    params: tuple[Param, ...]
    objectives: dict[str, str]
    cross: tuple[str, ...] = ()  # run every sampled row with each value of these
    firmware: dict[str, str] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)
    lines: dict[str, int] = field(default_factory=dict, compare=False)

    def where(self, key: str) -> str:
        """``FILE:LINE`` of a key written as ``section.key`` (the file alone when unknown)."""
        line = self.lines.get(key)
        return f"{self.source}:{line}" if line else self.source

    def error(self, key: str, text: str) -> CampaignError:
        return CampaignError(f"{self.where(key)}: {text}")

    def param(self, name: str) -> Param | None:
        return next((p for p in self.params if p.name == name), None)

    @property
    def digest(self) -> str:
        """What makes runs comparable: the kind, the options and the firmware's contents (not
        the sampler, nor where the ELFs lie)."""
        elfs = {
            k: hashlib.sha256(Path(v).read_bytes()).hexdigest() for k, v in self.firmware.items()
        }
        blob = json.dumps([self.kind, self.options, elfs], sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


_HEADER = re.compile(r"^\s*\[\s*([A-Za-z0-9_.\-]+)\s*\]\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+)\s*=")


def key_lines(text: str) -> dict[str, int]:
    """``section.key`` (and ``section``) -> the line it is written on (1-based)."""
    out: dict[str, int] = {}
    section = ""
    for number, line in enumerate(text.splitlines(), start=1):
        if m := _HEADER.match(line):
            section = m.group(1)
            out.setdefault(section, number)
        elif m := _KEY.match(line):
            out.setdefault(f"{section}.{m.group(1)}" if section else m.group(1), number)
    return out


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _param(name: str, value: Any, line: int, where: str) -> Param:
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {"min", "max", "steps", "log", "integer"})
        if unknown:
            raise CampaignError(
                f"{where}: {name}: unknown range key(s) {unknown}; a range has min, max and "
                "optionally steps (grid), log, integer"
            )
        low, high = value.get("min"), value.get("max")
        if not (_number(low) and _number(high)):
            raise CampaignError(f"{where}: {name}: a range needs numbers min < max, got {value}")
        lo, hi = float(cast(float, low)), float(cast(float, high))
        if not lo < hi:
            raise CampaignError(f"{where}: {name}: a range needs numbers min < max, got {value}")
        steps = value.get("steps")
        if steps is not None and not (isinstance(steps, int) and steps >= 2):
            raise CampaignError(f"{where}: {name}: steps must be an integer >= 2, got {steps!r}")
        log = bool(value.get("log", False))
        if log and lo <= 0:
            raise CampaignError(f"{where}: {name}: a log range needs min > 0, got {lo}")
        integer = bool(value.get("integer", False))
        return Param(name, line, range=Range(float(lo), float(hi), steps, log, integer))
    values = list(value) if isinstance(value, Sequence) and not isinstance(value, str) else [value]
    if not values:
        raise CampaignError(f"{where}: {name}: an empty list of values")
    for v in values:
        if not (_number(v) or isinstance(v, str | bool)):
            raise CampaignError(
                f"{where}: {name}: values must be numbers, strings or booleans, got {v!r}"
            )
    return Param(name, line, values=tuple(values))


def _table(doc: Mapping[str, Any], name: str, source: str, lines: dict[str, int]) -> dict:
    value = doc.get(name, {})
    if not isinstance(value, dict):
        raise CampaignError(f"{source}:{lines.get(name, 1)}: [{name}] must be a table")
    return value


def _int(table: Mapping[str, Any], key: str, default: int, lowest: int, where: str) -> int:
    v = table.get(key, default)
    if not (isinstance(v, int) and not isinstance(v, bool) and v >= lowest):
        raise CampaignError(f"{where}: {key} must be an integer >= {lowest}, got {v!r}")
    return v


def parse(
    text: str,
    source: str = "<campaign>",
    base: Path | None = None,
    firmware: Mapping[str, str] | None = None,
) -> Campaign:
    """The campaign in ``text``; ``base`` is where relative firmware paths start;
    ``firmware`` (label -> ELF path) replaces or adds entries of its ``[firmware]`` table."""
    lines = key_lines(text)

    def at(key: str) -> str:
        line = lines.get(key)
        return f"{source}:{line}" if line else source

    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{source}: not valid TOML: {exc}") from None
    for section in doc:
        if section not in SECTIONS:
            raise CampaignError(
                f"{at(section)}: unknown section [{section}]; expected {sorted(SECTIONS)}"
            )
    head = _table(doc, "campaign", source, lines)
    for key in head:
        if key not in {"name", "kind", "seed", "chunk"}:
            raise CampaignError(f"{at('campaign.' + key)}: unknown key {key!r} in [campaign]")
    kind = head.get("kind")
    if kind not in KINDS:
        raise CampaignError(f"{at('campaign.kind')}: kind must be one of {KINDS}, got {kind!r}")
    sampler = _table(doc, "sampler", source, lines)
    for key in sampler:
        if key not in {"method", "samples", "trials", "cross"}:
            raise CampaignError(f"{at('sampler.' + key)}: unknown key {key!r} in [sampler]")
    method = sampler.get("method", "grid")
    if method not in METHODS:
        raise CampaignError(
            f"{at('sampler.method')}: method must be one of {METHODS}, got {method!r}"
        )
    samples_key = "trials" if method == "optuna" else "samples"
    samples = _int(
        sampler,
        samples_key,
        0 if method == "grid" else 100,
        1 if method != "grid" else 0,
        at(f"sampler.{samples_key}"),
    )
    params_table = _table(doc, "parameters", source, lines)
    if not params_table:
        raise CampaignError(f"{at('parameters')}: [parameters] names no parameter")
    params = tuple(
        _param(name, value, lines.get(f"parameters.{name}", 0), at(f"parameters.{name}"))
        for name, value in params_table.items()
    )
    cross = sampler.get("cross", [])
    names = {p.name: p for p in params}
    if not (isinstance(cross, list) and all(isinstance(c, str) for c in cross)):
        raise CampaignError(f"{at('sampler.cross')}: cross must be a list of parameter names")
    for c in cross:
        if c not in names or names[c].values is None:
            raise CampaignError(
                f"{at('sampler.cross')}: cross names {c!r}, which is not a parameter with a "
                "list of values"
            )
    objectives = _table(doc, "objectives", source, lines)
    for key, sense in objectives.items():
        if sense not in ("min", "max"):
            raise CampaignError(
                f'{at("objectives." + key)}: objective {key} must be "min" or "max", got {sense!r}'
            )
    elfs: dict[str, Any] = dict(_table(doc, "firmware", source, lines))
    for label, path in (firmware or {}).items():
        elfs[label] = path
        lines[f"firmware.{label}"] = 0  # given on the command line: no line to name
    found: dict[str, str] = {}
    for label, path in elfs.items():
        if not isinstance(path, str):
            raise CampaignError(f"{at('firmware.' + label)}: firmware {label} must be a path")
        resolved = Path(path).expanduser()
        if not resolved.is_absolute() and base is not None and label not in (firmware or {}):
            resolved = base / resolved
        if not resolved.is_file():
            raise CampaignError(
                f"{at('firmware.' + label)}: firmware {label!r}: no such ELF file {resolved}"
            )
        found[label] = str(resolved.resolve())
    campaign = Campaign(
        source=source,
        text=text,
        name=str(head.get("name", Path(source).stem)),
        kind=kind,
        seed=_int(head, "seed", 0, 0, at("campaign.seed")),
        method=method,
        samples=samples,
        chunk=_int(head, "chunk", 0, 0, at("campaign.chunk")),
        params=params,
        objectives=dict(objectives),
        cross=tuple(cross),
        firmware=found,
        options=dict(_table(doc, "options", source, lines)),
        lines=lines,
    )
    if method != "grid":
        return campaign
    for p in params:
        if p.range is not None and p.range.steps is None:
            raise CampaignError(
                f"{campaign.where('parameters.' + p.name)}: {p.name}: a grid needs steps = N "
                "in each range (or a list of values)"
            )
    return campaign


def load(path: str | Path, firmware: Mapping[str, str] | None = None) -> Campaign:
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise CampaignError(f"{path}: no such campaign file") from None
    return parse(text, str(path), base=path.parent, firmware=firmware)
