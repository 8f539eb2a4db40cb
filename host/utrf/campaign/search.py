"""A search instead of a sweep (``method = "optuna"``): Optuna asks for each run given the
ones told so far (TPE for one objective, NSGA-II for several), and Dask runs them, as many
at once as there are workers. Optuna's study lives in memory: a campaign run again tells it
the runs already in the store (``add_trial``) before asking for more, so nothing is computed
twice and the search goes on where it stopped.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from utrf.campaign import engine, kinds, sampling
from utrf.campaign.spec import Campaign, Param
from utrf.campaign.store import Store


def _distribution(p: Param) -> Any:
    import optuna

    if p.range is not None:
        r = p.range
        if r.integer:
            return optuna.distributions.IntDistribution(int(r.low), int(r.high), log=r.log)
        return optuna.distributions.FloatDistribution(r.low, r.high, log=r.log)
    assert p.values is not None
    return optuna.distributions.CategoricalDistribution(list(p.values))


def _values(campaign: Campaign, row: dict[str, Any]) -> list[float] | None:
    """The objectives of a result row; None when the run failed or one is not finite."""
    if row.get("status") != "ok":
        return None
    out = []
    for name in campaign.objectives:
        v = row.get(name)
        if v is None or isinstance(v, str) or not math.isfinite(float(v)):
            return None
        out.append(float(v))
    return out


def run(
    campaign: Campaign,
    store: Store,
    to: kinds.Sink,
    *,
    address: str | None,
    workers: int | None,
    progress: engine.ProgressFn,
) -> engine.Summary:
    import optuna

    if not campaign.objectives:
        raise campaign.error("sampler.method", "an optuna search needs [objectives]")
    optuna.logging.set_verbosity(logging.WARNING)
    directions = [
        optuna.study.StudyDirection.MAXIMIZE if s == "max" else optuna.study.StudyDirection.MINIMIZE
        for s in campaign.objectives.values()
    ]
    sampler = (
        optuna.samplers.TPESampler(seed=campaign.seed)
        if len(directions) == 1
        else optuna.samplers.NSGAIISampler(seed=campaign.seed)
    )
    study = optuna.create_study(directions=directions, sampler=sampler)
    free = {p.name: _distribution(p) for p in campaign.params if not p.fixed}
    fixed = {p.name: p.values[0] for p in campaign.params if p.fixed and p.values}
    salt = engine.salt(campaign)
    done = store.read().to_pylist() if store.part_files() else []
    for row in done:  # what a killed search had finished
        if not all(k in row for k in free):
            continue
        values = _values(campaign, row)
        study.add_trial(
            optuna.trial.create_trial(
                params={k: row[k] for k in free},
                distributions=free,
                values=values,
                state=optuna.trial.TrialState.COMPLETE if values else optuna.trial.TrialState.FAIL,
            )
        )
    total = campaign.samples
    skipped = min(len(done), total)
    prog = engine._Progress(total, skipped, progress)
    options = {**campaign.options, "firmware_paths": campaign.firmware}
    kind = kinds.get(campaign.kind)
    want = ("status", *campaign.objectives)
    s = engine.Summary(total, skipped, 0, 0, 0.0, 0.0, 0, 0.0)
    t0 = time.monotonic()
    with engine.cluster(address, workers) as client:
        client.run(kinds.warm, campaign.kind)
        s.startup_s = time.monotonic() - t0
        s.workers = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
        from distributed import as_completed

        ac = as_completed()
        trials: dict[Any, tuple[Any, dict[str, np.ndarray], np.ndarray]] = {}
        asked = skipped
        start, s.started_at, cpu0 = time.perf_counter(), time.time(), time.process_time()
        while asked < total or trials:
            while asked < total and len(trials) < s.workers:
                trial = study.ask(free)
                cols = {k: np.array([v]) for k, v in {**fixed, **trial.params}.items()}
                words = sampling.key_words(cols, salt)
                fut = client.submit(
                    kinds.task,
                    kind.name,
                    options,
                    cols,
                    words,
                    to,
                    want,
                    key=f"utrf-{kind.name}-{int(words[0]):016x}-{trial.number}",
                )
                trials[fut] = (trial, cols, words)
                ac.add(fut)
                asked += 1
            fut = next(ac)
            trial, cols, words = trials.pop(fut)
            r = engine.outcome(fut, cols, np.arange(1), words, store)
            row = {k: v[0] for k, v in r.get("columns", {}).items()}
            values = _values(campaign, row or {"status": "failed"})
            if values is None:
                study.tell(trial, state=optuna.trial.TrialState.FAIL)
            else:
                study.tell(trial, values)
            prog.add_task(r)
            s.add_task(r)
            prog.tick(min(len(trials), s.workers))
        prog.tick(0, force=True)
        s.wall_s, s.driver_cpu_s = time.perf_counter() - start, time.process_time() - cpu0
    store.consolidate()
    s.ok, s.failed = prog.ok, prog.failed
    return s
