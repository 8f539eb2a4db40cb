"""The fuzzers in the suite: every committed input and every past crash replayed (the
firmware harnesses under ASan + UBSan), a short run of each harness (FUZZ_TEST_SECONDS,
default 20), and the seed corpora up to date with protocol/vectors."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import make_seeds  # noqa: E402
import runfuzz  # noqa: E402

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


def test_the_struct_harness_knows_every_reply_the_spec_names() -> None:
    """fuzz_struct.cpp's reply_id() (its oracle: each request answered with its reply) lists
    every request of protocol/spec.toml that names a reply."""
    import tomllib

    spec = tomllib.loads((HERE.parents[1] / "protocol" / "spec.toml").read_text())
    source = (HERE / "fuzz_struct.cpp").read_text()

    def camel(name: str) -> str:
        return "".join(part.capitalize() for part in name.split("_"))

    for msg in spec["message"]:
        if "reply" in msg:
            req, reply = camel(msg["name"]), camel(msg["reply"])
            line = f"case proto::{req}::kId: return proto::{reply}::kId;"
            assert line in source, f"fuzz_struct.cpp's reply_id() lacks {msg['name']}"
