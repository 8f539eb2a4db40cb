"""What every rig run shares: its two errors, its progress callback, and how it writes the
JSON files of its output directory (the CSVs are ``utrf.datalog``'s)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ProgressFn = Callable[[str], None]


class RunError(RuntimeError):
    """A run that cannot start or go on; the message says why and what to do."""


class RunStopped(RuntimeError):
    """The run stopped on a fault or an operator's interrupt; the data taken are kept."""


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` whole or not at all (a killed run leaves the previous file)."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=_json_default) + "\n")
    tmp.replace(path)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.floating | np.integer):
        return o.item()
    raise TypeError(f"not JSON: {type(o).__name__}")


def default_time() -> str:
    """The local time with its offset, for a run's ``meta.json``."""
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


def finite_mean(values: list[float] | np.ndarray) -> float:
    """The mean of the finite values; NaN when there are none."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else math.nan


RUN_KINDS = ("static-loading", "grasp-hold", "object-hold")


def run_kind(meta: dict[str, Any]) -> str:
    """Which run wrote a ``meta.json`` (one of RUN_KINDS), from its configuration's fields."""
    config = meta.get("config")
    if not isinstance(config, dict):
        raise RunError("meta.json has no run configuration ('config')")
    if "loads_kg" in config:
        return "static-loading"
    if "object" in config:
        return "object-hold"
    if "pose" in config and "tracked_finger" in config:
        return "grasp-hold"
    raise RunError(f"meta.json's configuration is of no known run (fields {sorted(config)})")


def default_out(kind: str, name: str) -> Path:
    """A new output directory for a run not given ``--out``: out/KIND/NAME-YYYYmmdd-HHMMSS."""
    return Path("out") / kind / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"
