"""Workers write their own parts: the same rows as the driver would write (the general path,
for workers that do not see the directory), a task run twice stores its runs once, the tasks
are cut the same way every time, and run keys survive the trip through their hex form."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from hypothesis import given, settings
from hypothesis import strategies as st

from utrf.campaign import engine, kinds, sampling
from utrf.campaign.store import Store

OPTIONS = {"function": "tests.campaign.funcs:square", "firmware_paths": {}}


def sink(tmp_path: Path, token: str | None = None) -> tuple[Store, kinds.Sink]:
    store = Store(tmp_path)
    store.parts.mkdir(parents=True)
    (store.parts / ".token").write_text("t0")
    return store, kinds.Sink(str(store.parts), token or "t0")


def test_a_worker_that_sees_the_directory_writes_what_the_driver_would(tmp_path: Path) -> None:
    cols = {"x": np.array([0.0, 2.0, -1.0]), "y": np.array([1.0, 1.0, 1.0])}
    words = sampling.key_words(cols, "s")
    store, to = sink(tmp_path / "a")
    fast = kinds.task("function", OPTIONS, cols, words, to, ("status", "g"))
    assert "table" not in fast and (store.parts / fast["part"]).is_file()
    assert (fast["rows"], fast["ok"], fast["columns"]["status"]) == (3, 2, ["ok", "ok", "failed"])
    other, blind = sink(tmp_path / "b", token="another campaign's")
    slow = kinds.task("function", OPTIONS, cols, words, blind, ())
    assert "part" not in slow and not other.part_files()  # the driver writes it
    other.append(slow["table"])
    drop = ["worker", "compute_s", "cpu_s"]
    a, b = (s.read().drop_columns(drop).to_pylist() for s in (store, other))
    assert a == b and [r["run_key"] for r in a] == sampling.run_keys(cols, "s").tolist()
    assert {r["x"]: r["f"] for r in a} == {0.0: 1.0, 2.0: 5.0, -1.0: None}


def test_a_task_run_twice_stores_its_runs_once(tmp_path: Path) -> None:
    cols = {"x": np.array([1.0, 3.0])}
    words = sampling.key_words(cols, "s")
    store, to = sink(tmp_path)
    first = kinds.task("function", OPTIONS, cols, words, to)
    again = kinds.task("function", OPTIONS, cols, words, to)  # its worker lost after writing
    assert first["part"] == again["part"] and len(store.part_files()) == 1
    assert store.read().num_rows == 2
    assert np.array_equal(store.done_words(), np.sort(words))
    assert not list(store.parts.glob(".*.tmp"))


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 5000), st.integers(1, 3000))
def test_tasks_cover_every_run_once_the_same_way_each_time(n: int, size: int) -> None:
    cut = engine.chunks(n, size)
    assert cut == engine.chunks(n, size)
    covered = np.concatenate([np.arange(n)[s] for s in cut]) if cut else np.zeros(0)
    assert np.array_equal(covered, np.arange(n))
    assert all(0 < s.stop - s.start <= size for s in cut)
    if n > engine.TAIL_CHUNKS * size and size >= 4:  # the tail is cut finer
        assert cut[-1].stop - cut[-1].start <= size // 4


@given(st.lists(st.integers(0, 2**64 - 1), max_size=50))
def test_run_keys_survive_their_hex_form(values: list[int]) -> None:
    words = np.array(values, dtype=np.uint64)
    keys = sampling.hex_keys(words)
    assert keys.tolist() == [f"{v:016x}" for v in values]
    assert np.array_equal(sampling.words_of(keys), words)


def test_a_part_is_named_by_its_runs(tmp_path: Path) -> None:
    store, _ = sink(tmp_path)
    t = kinds.table("function", OPTIONS, {"x": np.array([1.0])}, np.array(["00000000000000ab"]))
    path = store.append(t)
    assert path is not None and pq.read_table(path).num_rows == 1
    assert store.append(t) == path and len(store.part_files()) == 1
