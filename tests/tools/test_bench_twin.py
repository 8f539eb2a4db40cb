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


def test_the_mjcf_alone_steps_the_hand_for_the_simulated_time() -> None:
    r = bench_twin.engine_mjcf(0.05)
    assert r["sim"] == pytest.approx(0.05)
    assert r["cpu"] > 0


def test_the_section_gives_the_ratio_of_the_medians_and_each_engine() -> None:
    def runs(*values: float) -> list[dict]:
        return [{"wall": v, "cpu": v / 2, "load": 1.0} for v in values]

    alone = {tag: {"elf": {"cpu": 2.0}, "mjcf": {"cpu": 1.0}} for tag in ("new", "ref")}
    text = bench_twin.report(
        "f500c49",
        {"new": runs(5.0, 6.0, 50.0), "ref": runs(12.0, 11.0, 10.0), "one": runs(9.0, 8.0, 10.0)},
        alone,
        120,
        3,
    )
    assert text.startswith(bench_twin.BEGIN) and text.endswith(bench_twin.END)
    assert "**0.55**" in text  # median 6 against median 11: one slow run does not move it
    assert "wall **0.82**, CPU **0.82**" in text  # the one-thread twin: median 9 against 11
    # the new tree's engines beside its one-thread hold (CPU median 4.5 = 2 + 1 + 1.5)
    assert "2.0 s / 1.0 s / 1.5 s" in text
