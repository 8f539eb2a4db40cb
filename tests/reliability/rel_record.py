"""Where the reliability campaigns keep their figures: build/reliability/<name>.json, which
tools/reliability_doc.py turns into docs/reliability.md."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parents[2] / "build" / "reliability"


def record(name: str, key: str, value: Any) -> None:
    """Keep a measured figure: build/reliability/<name>.json, one entry per key."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    data[key] = value
    path.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
