"""What a campaign's runs are, by kind: which parameters and options a kind takes (checked
before anything runs), how many runs go in one task, and the task itself, which a Dask
worker executes (``execute``: a plain module-level function, pickled by reference).

- ``design``: finger designs through the vectorised models (``utrf.campaign.design``);
- ``grasp``: object holds on the twin, the real firmware on the emulated board
  (``utrf.campaign.grasp``);
- ``function``: any importable ``module:function`` called with each run's parameters,
  returning a dict of numbers (``[options] function = "..."``).

A run that raises is recorded as failed, with the exception as its reason; the campaign
goes on.
"""

from __future__ import annotations

import importlib
import os
import socket
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from utrf.campaign.sampling import Columns, row, row_count
from utrf.campaign.spec import Campaign, CampaignError
from utrf.campaign.store import columns_table


@dataclass(frozen=True)
class Kind:
    name: str
    check: Callable[[Campaign], None]  # CampaignError naming the line, before anything runs
    chunk: int  # runs per task by default
    evaluate: Callable[[dict[str, Any], Columns], Columns] | None  # vectorised over runs
    run_one: Callable[[dict[str, Any], dict[str, Any]], dict[str, Any]] | None  # one run


def get(name: str) -> Kind:
    if name == "design":
        from utrf.campaign import design

        return Kind("design", design.check, design.CHUNK, design.evaluate, None)
    if name == "grasp":
        from utrf.campaign import grasp

        return Kind("grasp", grasp.check, 1, None, grasp.run_one)
    if name == "function":
        return Kind("function", _check_function, 1, None, _call_function)
    raise CampaignError(f"unknown campaign kind {name!r}")


def _resolve(spec: object) -> Callable[..., Any]:
    if not isinstance(spec, str) or ":" not in spec:
        raise ValueError(f"function must be 'module:name', got {spec!r}")
    module, _, name = spec.partition(":")
    fn = getattr(importlib.import_module(module), name)
    if not callable(fn):
        raise ValueError(f"{spec} is not callable")
    return fn


def _check_function(campaign: Campaign) -> None:
    try:
        _resolve(campaign.options.get("function"))
    except (ValueError, ImportError, AttributeError) as exc:
        raise campaign.error("options.function", f"function: {exc}") from None


def _call_function(options: dict[str, Any], params: dict[str, Any]) -> dict[str, Any]:
    out = _resolve(options["function"])(**params)
    if not isinstance(out, dict):
        raise TypeError(f"{options['function']} returned {type(out).__name__}, not a dict")
    return out


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def execute(kind_name: str, options: dict[str, Any], cols: Columns, keys: np.ndarray) -> pa.Table:
    """One task: the runs ``cols`` (keys ``keys``) of a kind, with status and timing columns,
    as an Arrow table (made here, on the worker, not in the driver). Runs inside a Dask
    worker; never raises for a run's own failure."""
    return columns_table(_execute(kind_name, options, cols, keys))


def _execute(kind_name: str, options: dict[str, Any], cols: Columns, keys: np.ndarray) -> Columns:
    kind = get(kind_name)
    n = row_count(cols)
    start, start_cpu = time.perf_counter(), time.process_time()
    meta: Columns = {"run_key": keys, "worker": np.full(n, worker_name())}
    if kind.evaluate is not None:
        try:
            out = kind.evaluate(options, cols)
            status, error = np.full(n, "ok"), np.full(n, "", dtype=object)
        except Exception as exc:  # a task of many runs fails as one: each says why
            out, status = {}, np.full(n, "failed")
            error = np.full(n, _reason(exc), dtype=object)
        elapsed = np.full(n, (time.perf_counter() - start) / max(n, 1))
        cpu = np.full(n, (time.process_time() - start_cpu) / max(n, 1))
        return {
            **meta,
            "status": status,
            "error": error,
            "compute_s": elapsed,
            "cpu_s": cpu,
            **cols,
            **out,
        }
    assert kind.run_one is not None
    rows: list[dict[str, Any]] = []
    for i in range(n):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            result, status_i, error_i = kind.run_one(options, row(cols, i)), "ok", ""
        except Exception as exc:
            result, status_i, error_i = {}, "failed", _reason(exc)
        rows.append(
            {
                "status": status_i,
                "error": error_i,
                "compute_s": time.perf_counter() - t0,
                "cpu_s": time.process_time() - c0,
                **result,
            }
        )
    names: list[str] = []
    for r in rows:
        names += [k for k in r if k not in names]
    results = {k: np.array([r.get(k) for r in rows], dtype=object) for k in names}
    for k, v in results.items():
        if all(isinstance(x, int | float | np.number) and not isinstance(x, bool) for x in v):
            results[k] = v.astype(float)
    return {**meta, **cols, **results}


def _reason(exc: BaseException) -> str:
    """An exception as a one-line reason, with where it was raised."""
    frames = traceback.extract_tb(exc.__traceback__)
    at = f" (at {frames[-1].filename.rsplit('/', 1)[-1]}:{frames[-1].lineno})" if frames else ""
    return f"{type(exc).__name__}: {exc}{at}"
