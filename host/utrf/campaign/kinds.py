"""What a campaign's runs are, by kind: which parameters and options a kind takes (checked
before anything runs), how many runs go in one task, and the task itself, which a Dask
worker executes (``task``: a plain module-level function, pickled by reference).

- ``design``: finger designs through the vectorised models (``utrf.campaign.design``);
- ``grasp``: object holds on the twin, the real firmware on the emulated board
  (``utrf.campaign.grasp``);
- ``function``: any importable ``module:function`` called with each run's parameters,
  returning a dict of numbers (``[options] function = "..."``).

A run that raises is recorded as failed, with the exception as its reason; the campaign
goes on. A task (``task``) writes its runs' rows as a Parquet part itself when its worker
sees the campaign's directory, and returns a summary of a few numbers: the driver's work per
task does not grow with the task's rows.
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
import pyarrow.compute as pc

from utrf.campaign import store
from utrf.campaign.sampling import Columns, hex_keys, row, row_count
from utrf.campaign.spec import Campaign, CampaignError
from utrf.campaign.store import columns_table


@dataclass(frozen=True)
class Kind:
    name: str
    check: Callable[[Campaign], None]  # CampaignError naming the line, before anything runs
    chunk: int  # runs per task by default
    evaluate: Callable[[dict[str, Any], Columns], Columns] | None  # vectorised over runs
    run_one: Callable[[dict[str, Any], dict[str, Any]], dict[str, Any]] | None  # one run
    imports: tuple[str, ...] = ()  # what its runs import (``warm``)


def get(name: str) -> Kind:
    if name == "design":
        from utrf.campaign import design

        return Kind("design", design.check, design.CHUNK, design.evaluate, None)
    if name == "grasp":
        from utrf.campaign import grasp

        return Kind("grasp", grasp.check, 1, None, grasp.run_one, grasp.IMPORTS)
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


def warm(kind_name: str) -> None:
    """On each worker at the cluster's start (``client.run``): what the first task would
    import, imported now, so that it is start-up and not the first runs' time (seconds for
    the twin: MuJoCo, the emulator; pyarrow imports pandas the first time it converts a
    list)."""
    for module in get(kind_name).imports:
        importlib.import_module(module)
    columns_table({"x": np.array(["x"], dtype=object)})


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@dataclass(frozen=True)
class Sink:
    """Where a task's rows go: the campaign's ``runs/`` directory (absolute) and its token
    (``store.sees``)."""

    parts: str
    token: str


def task(
    kind_name: str,
    options: dict[str, Any],
    cols: Columns,
    words: np.ndarray,
    sink: Sink | None,
    want: tuple[str, ...] = (),
) -> dict[str, Any]:
    """One task on a Dask worker: the runs ``cols`` (key words ``words``), their rows written
    as a part in ``sink`` when this worker sees it (else returned as ``table`` for the driver
    to write), and a summary: rows, ok, the runs' compute and CPU time, the task's own time
    on the worker (start and end, wall clock), and the ``want`` columns as lists (what an
    Optuna search tells its study). Never raises for a run's own failure."""
    start, c0 = time.time(), time.process_time()
    t = table(kind_name, options, cols, hex_keys(words))
    out: dict[str, Any] = {
        "worker": worker_name(),
        "rows": t.num_rows,
        "ok": pc.sum(pc.equal(t.column("status"), "ok")).as_py() or 0,
        "compute_s": pc.sum(t.column("compute_s")).as_py() or 0.0,
        "cpu_s": pc.sum(t.column("cpu_s")).as_py() or 0.0,
        "columns": {
            n: t.column(n).to_pylist() if n in t.column_names else [None] * t.num_rows for n in want
        },
    }
    if sink is not None and store.sees(sink.parts, sink.token):
        out["part"] = store.write_part(sink.parts, t).name
    else:
        out["table"] = t
    out["task_cpu_s"] = time.process_time() - c0
    out["start"], out["end"] = start, time.time()
    return out


def table(kind_name: str, options: dict[str, Any], cols: Columns, keys: np.ndarray) -> pa.Table:
    """The runs ``cols`` (keys ``keys``) of a kind, with status and timing columns, as an
    Arrow table; in this process."""
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
