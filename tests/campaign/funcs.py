"""Functions for the ``function`` campaign kind in the tests: each call leaves a trace (a line
in the file named by ``UTRF_TEST_TRACE``), so a test counts how often each run was computed."""

from __future__ import annotations

import os
import time


def square(x: float, y: float = 0.0, sleep_s: float = 0.0) -> dict[str, float]:
    trace = os.environ.get("UTRF_TEST_TRACE")
    if trace:
        with open(trace, "a") as f:
            f.write(f"{x!r} {y!r}\n")
    if sleep_s:
        time.sleep(sleep_s)
    if x < 0:
        raise ValueError(f"x must be >= 0, got {x}")
    return {"f": x * x + y, "g": (x - 1) ** 2}


def set_trace(path: str) -> None:
    """On a worker (``client.run``): where ``square`` leaves its trace."""
    os.environ["UTRF_TEST_TRACE"] = path
