"""The fuzzers in the suite: every committed input and every past crash replayed (the
firmware harnesses under ASan + UBSan), a short run of each harness (FUZZ_TEST_SECONDS,
default 20), and the seed corpora up to date with protocol/vectors."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import make_seeds  # tests/fuzz: on the path as this test's folder (pytest's rootdir insertion)
import pytest
import runfuzz

HERE = Path(__file__).resolve().parent

SECONDS = float(os.environ.get("FUZZ_TEST_SECONDS", "20"))


@pytest.fixture(scope="module")
def fuzzers(make: Callable[..., None]) -> None:
    make("fuzz-build")


@pytest.mark.parametrize("harness", runfuzz.HARNESSES)
def test_the_corpus_and_every_past_crash_replay_clean(fuzzers: None, harness: str) -> None:
    code, out = runfuzz.replay(harness)
    assert code == 0, out[-4000:]


@pytest.mark.parametrize("harness", runfuzz.HARNESSES)
def test_a_short_fuzzing_run_finds_nothing(fuzzers: None, harness: str, tmp_path: Path) -> None:
    res = runfuzz.run(harness, SECONDS, None, tmp_path)
    assert res["findings"] == [], (res.get("finding_text"), (tmp_path / f"{harness}.log"))
    assert res.get("number_of_executed_units", 0) > 100
    assert res.get("coverage_edges", 0) > 0


def test_the_seed_corpora_match_the_vectors(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(make_seeds, "HERE", tmp_path)
    make_seeds.main()
    for harness in runfuzz.HARNESSES:
        made = {p.name: p.read_bytes() for p in (tmp_path / "corpus" / harness).iterdir()}
        kept = {
            p.name: p.read_bytes()
            for p in (HERE / "corpus" / harness).iterdir()
            if p.name.startswith("seed-")
        }
        assert made == kept, f"tests/fuzz/corpus/{harness} is stale: run tests/fuzz/make_seeds.py"
