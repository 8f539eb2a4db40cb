"""The grasp hold on the emulated board: hits are found in the data, the fingers recover,
nothing faults; the report's figures recomputed from the samples."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from utrf.cli import main
from utrf.hil.grasp_hold import analysis, report, run
from utrf.hil.grasp_hold import config as gh
from utrf.hil.rig import EmulatedTruth, open_emulated
from utrf.hil.runs import RunError


@pytest.mark.slow
def test_hits_are_found_and_the_grasp_recovers(
    firmware_elf: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "grasp"
    config = gh.GraspHoldConfig(duration_s=5.0, hits=2, seed=4, sample_hz=100.0)
    rig = open_emulated(seed=4, tracked_finger=1, truth=EmulatedTruth(actuator=None))
    try:
        run.run(rig, config, out, progress=lambda _s: None)
    finally:
        rig.close()
    result = report.write(out)
    assert result["complete"] and not result["faults"]
    hits = result["hits_applied"]
    assert len(hits) == 2
    for h in hits:  # each hit shows as a disturbance of its finger, which then recovers
        events = result["fingers"][h["finger"]]["disturbances"]
        near = [e for e in events if 0 <= e["peak_s"] - h["time_s"] < 0.2]
        assert near, (h, events)
        assert abs(near[0]["largest_deviation_rad"]) > 0.03
        assert near[0]["recovery_s"] is not None and near[0]["recovery_s"] < 0.5
    hit_fingers = {h["finger"] for h in hits}
    for name, p in result["fingers"].items():
        if name not in hit_fingers:
            assert p["disturbances"] == []  # a quiet finger has none
        assert p["modes"] == ["GRASP"]  # all five closed on the bottle and held it
        assert abs(p["drift_rad"]) < 0.01
    assert result["unrecovered_disturbances"] == 0
    # drift recomputed from the samples: end window against the baseline window
    with (out / "samples.csv").open() as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["time_s"]) for r in rows])
    th = np.array([float(r["middle_theta2_rad"]) for r in rows])
    base, end = th[t < config.baseline_s].mean(), th[t >= t[-1] - config.baseline_s].mean()
    assert result["fingers"]["middle"]["drift_rad"] == pytest.approx(end - base, abs=1e-9)
    cur = np.array([float(r["middle_current_a_a"]) for r in rows])
    assert result["fingers"]["middle"]["current_a_a"]["max"] == pytest.approx(cur.max())
    assert (out / "grasp_hold.png").exists()
    # The figure shows what the run concludes: each finger's drift, each disturbance's
    # deviation and recovery, the tracked tip.
    import matplotlib.pyplot as plt

    drawn: dict[str, object] = {}
    monkeypatch.setattr(plt.Figure, "savefig", lambda fig, *_a, **_k: drawn.update(fig=fig))
    samples = analysis.read_samples(out, list(result["fingers"]))
    report.plot(result, samples, list(result["fingers"]), tmp_path / "again.png")
    drift_ax, dist_ax, tip_ax = drawn["fig"].axes  # type: ignore[attr-defined]
    labels = [line.get_label() for line in drift_ax.get_lines()]
    for name, p in result["fingers"].items():
        assert f"{name}: drift {math.degrees(p['drift_rad']):+.2f} deg" in labels
    peaks = sorted(
        float(line.get_ydata()[0]) for line in dist_ax.get_lines() if line.get_marker() == "o"
    )
    expected = sorted(
        math.degrees(e["largest_deviation_rad"])
        for p in result["fingers"].values()
        for e in p["disturbances"]
    )
    assert peaks == pytest.approx(expected) and len(peaks) >= 2
    texts = [a.get_text() for a in dist_ax.texts]
    assert all(t.endswith(" s") for t in texts) and len(texts) == len(expected)
    assert "1 s mean" in [line.get_label() for line in tip_ax.get_lines()]
    assert "moved" in tip_ax.get_title()
    # the results come from the logs alone: `utrf hil analyse` rebuilds them
    before = json.loads((out / "results.json").read_text())
    (out / "results.json").unlink()
    assert main(["hil", "analyse", str(out)]) == 0
    assert json.loads((out / "results.json").read_text()) == before


def test_a_pose_that_is_not_a_grasp_is_refused(
    firmware_elf: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = open_emulated(seed=0, tracked_finger=1, truth=EmulatedTruth(actuator=None))
    try:
        with pytest.raises(RunError, match=r"not a grasp pose; grasp poses: .*grasp-bottle"):
            run.run(rig, gh.GraspHoldConfig(pose="fist", duration_s=3.0), tmp_path / "g")
        with pytest.raises(RunError, match="'nope' is not a grasp pose"):
            run.run(rig, gh.GraspHoldConfig(pose="nope", duration_s=3.0), tmp_path / "g")
    finally:
        rig.close()
    assert not (tmp_path / "g").exists()  # refused before anything was written
    # the command says so and exits 2 (bad input), with nothing left behind
    cli = ["hil", "grasp-hold", "--emulated", "--out", str(tmp_path / "c"), "--quiet"]
    assert main([*cli, "--pose", "nope", "--duration-s", "3"]) == 2
    assert "'nope' is not a grasp pose" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
    with pytest.raises(RunError, match="hold of at least"):
        gh.GraspHoldConfig(duration_s=2.0, hits=1)


def test_disturbance_detection_on_a_known_trace() -> None:
    t = np.arange(0, 3, 0.01)
    dev = np.zeros_like(t)
    dev[(t >= 1.0) & (t < 1.3)] = -0.05  # knocked off, back after 0.3 s
    dev[t >= 2.5] = 0.03  # and never back
    ev = analysis._events(t, dev, detect=0.02, recover=0.01)
    assert len(ev) == 2
    assert ev[0]["start_s"] == pytest.approx(1.0) and ev[0]["recovery_s"] == pytest.approx(0.3)
    assert ev[0]["largest_deviation_rad"] == pytest.approx(-0.05)
    assert ev[1]["recovery_s"] is None


def _hold(
    tmp: Path, ahead: bool, batched: bool = False, line: bool = False, **config_kw: float
) -> tuple[dict[str, bytes], dict[str, int], dict[str, int]]:
    kw: dict = {"duration_s": 3.0, "hits": 1, "seed": 2, "sample_hz": 50.0, **config_kw}
    config = gh.GraspHoldConfig(**kw)
    rig = open_emulated(seed=2, tracked_finger=1, truth=EmulatedTruth(actuator=None))
    rig.ahead, rig.batched = ahead, batched
    board = rig.board
    if line:  # damaged frames both ways: heartbeats the board never acks, frames it garbles
        board.set_line_faults("to_board", corrupt=0.03)
        board.set_line_faults("to_host", corrupt=0.0005, drop=0.0005)
    runs: list[int] = []
    batch = board.run_ahead_stops
    board.run_ahead_stops = lambda targets, *a, **kw: (
        runs.append(len(targets)),
        batch(targets, *a, **kw),
    )
    carried: list[object] = []  # the harness's heartbeat rule carried to the next batch
    rule = board.run_ahead_beats_next
    board.run_ahead_beats_next = lambda: (r := rule(), r is not None and carried.append(r))[0]
    try:
        run.run(rig, config, tmp, progress=lambda _s: None)
        stats, rx = dict(board.stats), board.rx_timing()  # every byte's arrival, to the cycle
        stats["batched_runs"], stats["batched_stops"] = len(runs), sum(runs)
        stats["carried_runs"] = len(carried)
        stats["cycle"] = round(board.sim_time * 16e6)
    finally:
        rig.close()
    files = {n: (tmp / n).read_bytes() for n in ("samples.csv", "hits.csv", "telemetry.csv")}
    return files, stats, rx


@pytest.mark.slow
def test_the_board_running_ahead_takes_the_same_hold_to_the_bit(
    firmware_elf: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rig.each_period's two ways: the board running on to the next sample on its own thread
    while the last is written (SimLink.sleep_each), and sleeping to each sample: the same
    samples, hits, telemetry (each frame stamped where it was noticed) and heartbeats (the
    bytes the board took, at the same cycles), to the bit; also with the plant on a thread
    of its own beside the board's, and the fast path: the harness hitting and taking the
    truth at each sample itself, the board running through several a run
    (SimLink.stops_each)."""
    plain, stats_p, rx_p = _hold(tmp_path / "plain", False)
    assert stats_p.pop("batched_runs") == 0 and stats_p.pop("batched_stops") == 0
    assert stats_p.pop("carried_runs") == 0
    for threads, batched in (("1", False), ("2", False), ("1", True), ("2", True)):
        monkeypatch.setenv("UTRF_TWIN_THREADS", threads)
        ahead, stats_a, rx_a = _hold(tmp_path / f"ahead{threads}{batched}", True, batched)
        assert ahead["samples.csv"].count(b"\n") > 140 and ahead["hits.csv"].count(b"\n") == 2
        assert ahead == plain
        runs, stops = stats_a.pop("batched_runs"), stats_a.pop("batched_stops")
        carried = stats_a.pop("carried_runs")
        if batched:  # the harness sends the heartbeats: up to 64 samples a run
            assert stops >= 145 and runs <= stops / 30, (runs, stops)
            # each batch after the first started from the harness's rule, before the engine
            # took the last one's frames (and stood where the rule said: checked as it ran)
            assert carried >= runs - 1 and carried >= 2, (carried, runs)
        else:
            assert runs == 0
        # the sleep counter adds a cycle at each SLEEP entry: a run ahead entered 9-14 fewer of
        # 57.7 M cycles in 2 of about 20 runs, everything else the same (open: docs/mujoco.md)
        slept_a, slept_p = stats_a.pop("sleep_cycles"), stats_p.pop("sleep_cycles")
        assert abs(slept_a - slept_p) <= 64 and slept_p > 0
        assert stats_a == stats_p and stats_a["rx_host_bytes"] > 0
        stats_p["sleep_cycles"] = slept_p
        assert rx_a == rx_p


@pytest.mark.slow
def test_more_hits_a_batch_than_the_harness_takes_come_out_the_same(
    firmware_elf: Path, tmp_path: Path
) -> None:
    """400 light hits in 3 s (all within 0.4 s of it, one a millisecond): a batch ends before
    the first hit beyond the 16 the harness takes a run could fall due, so there the samples
    are taken the general way, and the hold is sleep_each's to the bit (samples, every hit,
    telemetry)."""
    light = {"hits": 400, "hit_impulse_n_s": 0.002}
    plain, stats_p, _ = _hold(tmp_path / "ahead", True, False, **light)
    batched, stats_b, _ = _hold(tmp_path / "batched", True, True, **light)
    assert batched["hits.csv"].count(b"\n") == 401 and batched == plain
    # batches before and after the hits, the general way among them
    assert stats_b["batched_runs"] >= 3 and 100 < stats_b["batched_stops"] < 140
    for st in (stats_p, stats_b):
        st.pop("batched_runs"), st.pop("batched_stops"), st.pop("sleep_cycles")
        st.pop("carried_runs")
    assert stats_b == stats_p


@pytest.mark.slow
def test_a_noisy_line_comes_out_the_same(firmware_elf: Path, tmp_path: Path) -> None:
    """The harness's heartbeats on a noisy line: heartbeats damaged on the way (no ack: the
    next falls due a period after the last one sent) and the board's frames damaged (the
    harness cannot place them: the batch ends at the next sample, and the engine goes on the
    general way). The hold is sleep_each's to the bit, and the batches still ran."""
    plain, stats_p, rx_p = _hold(tmp_path / "ahead", True, False, line=True)
    batched, stats_b, rx_b = _hold(tmp_path / "batched", True, True, line=True)
    assert stats_p["rx_corrupted"] > 5 and stats_p["tx_corrupted"] > 5, stats_p
    assert batched["samples.csv"].count(b"\n") > 140 and batched == plain
    runs, stops = stats_b.pop("batched_runs"), stats_b.pop("batched_stops")
    assert stops > 75 and runs > 5  # frozen batches, ended early
    # a frozen rule is not carried on: the engine takes those frames before the next batch
    assert 0 < stats_b.pop("carried_runs") < runs
    for st in (stats_p, stats_b):
        st.pop("batched_runs", None), st.pop("batched_stops", None), st.pop("sleep_cycles")
        st.pop("carried_runs", None)
    assert stats_b == stats_p and rx_b == rx_p


def test_the_decimated_line_keeps_every_extreme_and_gap() -> None:
    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(0.0, 120.0, 6001))
    y = np.cumsum(rng.normal(size=x.size))
    y[1000:1400] = np.nan  # a gap wider than a column: the line breaks there
    y[3000] = np.nan  # one missing sample within a column
    columns = 200
    xs, ys = report.decimate(x, y, columns)
    assert len(xs) <= 2 * columns and np.all(np.diff(xs) > 0)
    col = np.minimum(((x - x[0]) * (columns / (x[-1] - x[0]))).astype(int), columns - 1)
    kept = np.minimum(((xs - x[0]) * (columns / (x[-1] - x[0]))).astype(int), columns - 1)
    for c in np.unique(col):  # each column's lowest and highest sample are drawn
        whole, drawn = y[col == c], ys[kept == c]
        if np.isfinite(whole).any():
            assert np.nanmin(drawn) == np.nanmin(whole) and np.nanmax(drawn) == np.nanmax(whole)
        else:
            assert np.isnan(drawn).all() and len(drawn) >= 1
    assert np.nanmax(ys) == np.nanmax(y) and np.nanmin(ys) == np.nanmin(y)
    gap = (xs > x[1001]) & (xs < x[1399])
    assert gap.any() and np.isnan(ys[gap]).all()
    short = report.decimate(x[:300], y[:300], columns)  # fewer points than it keeps: whole
    assert np.array_equal(short[0], x[:300])
    assert np.array_equal(short[1], y[:300], equal_nan=True)


def test_samples_kept_in_memory_are_the_files(tmp_path: Path) -> None:
    names = ["thumb", "index", "middle", "ring", "little"]
    columns = gh.sample_columns(names)
    finger = ",0.10000,0.20000,0.300,0.000,GRASP,0,0.1000"
    lines = [f"{k * 0.02:.6f},baseline,0.1,0.2,0.3,1,{k}{finger * 5}\n" for k in range(4)]
    (tmp_path / "samples.csv").write_text(",".join(columns) + "\n" + "".join(lines) + "0.08,ho")
    kept = analysis.parse_samples(lines, names)
    read = analysis.read_samples(tmp_path, names)  # the row cut by a kill is left out
    assert analysis.count(read) == analysis.count(kept) == 4
    for c in columns:
        assert np.array_equal(read[c], kept[c]), c
    with (tmp_path / "samples.csv").open() as f:  # the CSV module reads the same values
        rows = list(csv.DictReader(f))[:4]
    assert [float(r["index_theta2_rad"]) for r in rows] == kept["index_theta2_rad"].tolist()
    assert kept["thumb_mode"].tolist() == ["GRASP"] * 4 and kept["phase"][0] == "baseline"
    bad = [lines[0], lines[1].replace(",0.300,", ",oops,", 1)]
    with pytest.raises(ValueError, match=r"column 'thumb_duty_a', row 2: 'oops' is not a number"):
        analysis.parse_samples(bad, names)
