"""``make bench-twin``'s parts: each engine alone, and the section it writes."""

from __future__ import annotations

from pathlib import Path

import pytest

from tools import bench_twin


@pytest.mark.slow
def test_the_elf_alone_runs_the_firmware_with_no_plant(
    firmware_elf: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(bench_twin.REPO_ROOT)  # the checkout's build/, as the benchmark runs it
    r = bench_twin.engine_elf(0.2)
    assert r["held"]  # five fingers stayed in POSITION: no stall with the encoders held still
    assert r["sim"] == pytest.approx(0.2, abs=1e-3)
    assert r["cpu"] > 0


@pytest.mark.slow
def test_the_hold_by_thread_names_the_harness_threads(
    firmware_elf: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(bench_twin.REPO_ROOT)
    monkeypatch.setenv("UTRF_TWIN_THREADS", "2")
    r = bench_twin.engine_threads(4.0)
    assert r["twin_threads"] == 2 and 0 <= r["inline"] <= r["periods"]
    assert r["wait"] >= 0 and (r["wait"] > 0) == (r["inline"] < r["periods"])
    assert {"client", "utrf-board", "utrf-plant"} <= set(r["threads"])
    assert r["threads"]["client"] > 0 and r["threads"]["utrf-board"] > 0


def test_the_mjcf_alone_steps_the_hand_for_the_simulated_time() -> None:
    r = bench_twin.engine_mjcf(0.05)
    assert r["sim"] == pytest.approx(0.05)
    assert r["cpu"] > 0


@pytest.mark.parametrize("threads", [1, 2])
def test_the_section_gives_the_ratio_of_the_medians_and_each_engine(threads: int) -> None:
    def runs(*values: float) -> list[dict]:
        return [{"wall": v, "cpu": v / 2, "load": 1.0} for v in values]

    alone: dict = {tag: {"elf": {"cpu": 2.0}, "mjcf": {"cpu": 1.0}} for tag in ("new", "ref")}
    alone["threads"] = {"threads": {"client": 3.0, "utrf-board": 9.0, "utrf-plant": 4.0,
                                    "python": 0.5}, "wall": 12.0, "inline": 300,
                        "periods": 1200, "twin_threads": threads, "wait": 1.5}  # fmt: skip
    alone["threads_other"] = {"threads": {"client": 2.0, "utrf-board": 7.0, "utrf-plant": 5.0},
                              "wall": 11.0, "inline": 600, "periods": 1200, "wait": 2.5,
                              "twin_threads": 3 - threads}  # fmt: skip
    text = bench_twin.report(
        "f500c49",
        {"new": runs(5.0, 6.0, 50.0), "ref": runs(12.0, 11.0, 10.0), "other": runs(9.0, 8.0, 10.0)},
        alone,
        120,
        3,
        threads,
    )
    assert text.startswith(bench_twin.BEGIN) and text.endswith(bench_twin.END)
    assert "**0.55**" in text  # median 6 against median 11: one slow run does not move it
    assert "wall **0.82**, CPU **0.82**" in text  # the other count's twin: median 9 against 11
    assert f"its twin on {threads} thread" in text
    assert f"`UTRF_TWIN_THREADS={3 - threads}`" in text
    # the engines beside the one-thread hold: the other count's runs when the checkout's own
    # choice is two (CPU median 4.5 = 2 + 1 + 1.5), else its own (3.0 = 2 + 1 + 0)
    assert ("2.0 s / 1.0 s / 1.5 s" if threads == 2 else "2.0 s / 1.0 s / 0.0 s") in text
    # by thread: the client, the board's, the plant's, the rest; the inline share with two
    assert "3.0 s / 9.0 s / 4.0 s / 0.5 s" in text
    assert ("plant itself in 25 % of the periods and waited 1.5 s" in text) == (threads == 2)
    # and the other count's by-thread run beside it, its hand-overs' cost with two
    assert text.count("hold by thread") == 2 and "2.0 s / 7.0 s / 5.0 s / 0.0 s" in text
    assert ("plant itself in 50 % of the periods and waited 2.5 s" in text) == (threads == 1)
