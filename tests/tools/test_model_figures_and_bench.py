"""The commands that make the docs' figures and the benchmark run, and say what they measured."""

from __future__ import annotations

from pathlib import Path

import pytest

from tools import bench_models as bench
from tools import model_figures as figures


def test_figures_command_writes_the_three_pngs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert figures.main([str(tmp_path)]) == 0
    for name in ("workspace.png", "stiffness.png", "model_gap.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and 5_000 < len(data) < 200_000
    out = capsys.readouterr().out
    assert "effective modulus" in out and "N/m" in out


def test_bench_updates_only_its_section(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    md = tmp_path / "benchmarks.md"
    md.write_text(
        "# Benchmarks\n\n## Firmware\n\nkeep me\n\n"
        "## Models\n\nstale-marker\n\n## Protocol\n\nme too\n"
    )
    assert (
        bench.main(
            [
                "--update",
                str(md),
                "--batch-size",
                "200",
                "--repeats",
                "3",
                "--stress-cases",
                "5",
                "--json",
                str(tmp_path / "b.json"),
            ]
        )
        == 0
    )
    text = md.read_text()
    assert "keep me" in text and "me too" in text and "stale-marker" not in text
    assert text.count("## Models") == 1 and "solves per second" in text
    assert "one step of the whole hand" in text and "equilibrium in MuJoCo" in text
    assert text.index("## Firmware") < text.index("## Models") < text.index("## Protocol")
    fresh = tmp_path / "new.md"
    bench.update_section(fresh, "## Models\n\nx\n")
    assert fresh.read_text() == "# Benchmarks\n\n## Models\n\nx\n"
