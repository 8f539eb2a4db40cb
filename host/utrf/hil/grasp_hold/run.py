"""Taking a grasp hold's data: close on the object, hold, record every sample as it is taken
(``utrf.hil.grasp_hold``); the results are :mod:`utrf.hil.grasp_hold.analysis`'s."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import CsvLog
from utrf.hil.grasp_hold.config import (
    HIT_COLUMNS,
    GraspHoldConfig,
    sample_columns,
    sample_line,
)
from utrf.hil.rig import Rig
from utrf.hil.runs import ProgressFn, RunError, RunStopped, write_json
from utrf.models import kinematics


def run(
    rig: Rig,
    config: GraspHoldConfig,
    out: Path,
    *,
    progress: ProgressFn = print,
    meta: dict[str, Any] | None = None,
) -> list[str]:
    """Close on the object, hold, record every sample as it is taken (the results:
    ``report.write``, from the files); RunStopped on a fault (the data stay). Returns the
    rows written to ``samples.csv`` (kept: the analysis need not read them back)."""
    hand = rig.hand
    names = list(hand.fingers)
    if (out / "samples.csv").exists():
        raise RunError(f"{out} already holds a grasp hold; give a new --out")
    pose = hand.poses.get(config.pose)
    if pose is None or pose.grasp is None:  # refused before anything is written
        grasps = [p for p in hand.poses if hand.poses[p].grasp is not None]
        raise RunError(f"pose {config.pose!r} is not a grasp pose; grasp poses: {grasps}")
    out.mkdir(parents=True, exist_ok=True)
    goal = pose.theta2(hand.geometry)
    write_json(out / "meta.json", {"config": config.to_json(), **(meta or {})})
    hand.start_log(out / "telemetry.csv")
    hand.clear_faults()
    hand.pose("open", duration=0.5)
    closing = [i for i in range(len(names)) if goal[i] > 0.2]
    if rig.board is not None:
        for i in closing:
            rig.board.block_finger(i, config.contact_fraction * goal[i], direction="flexion")
    elif rig.operator is not None:
        rig.operator.confirm(f"Place the object for {config.pose!r} in the open hand")
    progress(f"closing on the object: {config.pose} (GRASP, effort {pose.grasp.effort:g})")
    hand.pose(config.pose, duration=1.0, timeout=5.0)
    hand.clock.sleep(0.5)
    opening = {}
    for i in closing:
        g = hand.geometry.fingers[i].geometry
        jac = kinematics.jacobian(g, kinematics.q_from_theta2(g, config.contact_fraction * goal[i]))
        opening[i] = -np.asarray(jac) / np.linalg.norm(jac)  # the tip's way when q shrinks
    hits = config.hit_plan(closing, opening) if rig.board is not None else []
    if rig.board is None and rig.operator is not None:
        rig.operator.say(
            f"holding for {config.duration_s:g} s: hit the fingers with the hammer as you like; "
            "the run records (Ctrl-C stops it, the data stay)"
        )
    seen = len(hand.faults_seen)
    period = 1.0 / config.sample_hz
    t0 = rig.now()
    next_report = 0.0
    lines: list[str] = []
    with (
        CsvLog(out / "samples.csv", sample_columns(names)) as samples,
        CsvLog(out / "hits.csv", HIT_COLUMNS) as hit_log,
    ):

        def take(t: float) -> tuple[float, Any, np.ndarray] | None:
            """At the sample's time, the board stopped there: the hits due, the truth (the
            tracker's reading finished after the board has started again)."""
            if t > config.duration_s:
                return None
            while hits and hits[0][0] <= t:
                _, f, imp = hits.pop(0)
                rig.hit(f, imp, config.hit_duration_s)
                log_hit(rig.now() - t0, f, imp)
            return t, rig.tracker.read_later(), rig.currents()

        def write_hit(t: float, f: int, imp: tuple[float, float]) -> None:
            hit_log.write([f"{t:.6f}", f, imp[0], imp[1], config.hit_duration_s])

        def log_hit(t: float, f: int, imp: tuple[float, float]) -> None:
            write_hit(t, f, imp)
            if stops is not None:
                stops.applied += 1  # by take(): the harness's list moves on with it

        def made(t: float, reading: Any, cur: np.ndarray, applied: int) -> Any:
            """take()'s value from what the harness did and recorded at the sample's time."""
            if t > config.duration_s:
                return None
            for _ in range(applied):
                _, f, imp = hits.pop(0)
                write_hit(t, f, imp)
            return t, reading, cur

        # the fast path: the harness hits and takes the truth at each sample time itself, the
        # board running through many samples a run (Rig.batch_stops; None: take() each time)
        stops = rig.batch_stops(t0, config.duration_s, list(hits), config.hit_duration_s, made)

        # the board runs on to the next sample while this one is written; closed on the way
        # out (a stop too), so the board has stopped before anything else uses it
        with contextlib.closing(rig.each_period(t0, period, take, stops)) as periods:
            for t, reading, cur in periods:
                s = reading()
                st = hand.latest
                phase = "baseline" if t < config.baseline_s else "hold"
                line = sample_line(t, phase, s, st, cur[: len(names)])
                samples.write_line(line)
                lines.append(line)
                new = hand.faults_seen[seen:]
                if new:
                    raise RunStopped(f"grasp hold at {t:.2f} s: {new[0]}")
                if t >= next_report:
                    progress(
                        f"hold {t:7.1f} / {config.duration_s:g} s  "
                        + "  ".join(
                            f"{n} {math.degrees(st.fingers[i].theta2):6.1f} deg"
                            for i, n in enumerate(names)
                        )
                        if st is not None
                        else f"hold {t:.1f} s"
                    )
                    next_report += max(config.duration_s / 20, 1.0)
    return lines
