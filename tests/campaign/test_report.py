"""The report's statistics: the Pareto front against brute force, Wilson intervals, the
paired A/B difference; the grasp tables and the A/B verdict from a results table."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa
from hypothesis import given, settings
from hypothesis import strategies as st

from utrf.campaign import grasp_report, report, spec


def brute_front(v: np.ndarray, senses: list[str]) -> set[int]:
    m = np.where(np.array([s == "max" for s in senses]), -v, v)
    out = set()
    for i in range(len(m)):
        dominated = ((m <= m[i]).all(1) & (m < m[i]).any(1)).any()
        if not dominated:
            out.add(i)
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 400), st.integers(2, 3), st.integers(0, 2**16), st.booleans())
def test_the_front_is_the_brute_force_front(n: int, k: int, seed: int, coarse: bool) -> None:
    rng = np.random.default_rng(seed)
    v = rng.integers(0, 6, (n, k)).astype(float) if coarse else rng.random((n, k))  # ties too
    senses = ["max", "min", "max"][:k]
    assert set(report.pareto_front(v, senses).tolist()) == brute_front(v, senses)


def test_the_front_of_many_points_crosses_blocks() -> None:
    rng = np.random.default_rng(1)
    v = rng.random((9000, 2))
    got = set(report.pareto_front(v, ["max", "max"]).tolist())
    order = np.argsort(-v[:, 0])
    best, expect = -math.inf, set()
    for i in order:  # the 2-D staircase
        if v[i, 1] > best:
            expect.add(int(i))
            best = v[i, 1]
    assert got == expect


def test_wilson_interval() -> None:
    lo, hi = report.wilson(8, 10)  # textbook: 0.490 to 0.943
    assert (round(lo, 3), round(hi, 3)) == (0.49, 0.943)
    assert report.wilson(0, 10)[0] == 0.0 and math.isclose(report.wilson(10, 10)[1], 1.0)


def test_paired_difference_and_mcnemar() -> None:
    a = np.array([True] * 20 + [False] * 20)
    b = np.array([True] * 20 + [True] * 15 + [False] * 5)
    out = report.paired_difference(a, b)
    assert out["difference"] == 15 / 40 and out["only_b_held"] == 15 and out["only_a_held"] == 0
    assert out["ci_low"] < 15 / 40 < out["ci_high"] and out["ci_low"] > 0
    assert out["mcnemar_p"] < 1e-3  # 15 discordant pairs all one way
    same = report.paired_difference(a, a)
    assert same["difference"] == 0 and same["mcnemar_p"] == 1.0


def test_grasp_tables_and_the_ab_verdict(tmp_path: Path) -> None:
    (tmp_path / "a.elf").write_bytes(b"a")
    (tmp_path / "b.elf").write_bytes(b"b")
    c = spec.parse(
        '[campaign]\nkind = "grasp"\n[sampler]\nmethod = "grid"\n[parameters]\n'
        'firmware = ["a", "b"]\nmass_kg = [0.1, 0.5]\nseed = [0, 1, 2, 3, 4]\n'
        '[firmware]\na = "a.elf"\nb = "b.elf"\n',
        "c.toml",
        base=tmp_path,
    )
    rows = []
    for fw in ("a", "b"):
        for mass in (0.1, 0.5):
            for seed in range(5):
                held = mass < 0.3 or (fw == "b" and seed < 3)  # b holds 3 more heavy ones
                rows.append({"status": "ok", "firmware": fw, "mass_kg": mass, "seed": seed,
                             "held": held, "broke": None})  # fmt: skip
    rows.append({"status": "failed", "firmware": "a", "mass_kg": 0.1, "seed": 9, "held": None,
                 "broke": None})  # fmt: skip
    out = grasp_report.grasps(c, pa.Table.from_pylist(rows), tmp_path, plots=True)
    assert out["runs"] == 20 and out["held"] == 13
    by_mass = {r["value"]: (r["held"], r["runs"]) for r in out["by"]["mass_kg"]}
    assert by_mass == {0.1: (10, 10), 0.5: (3, 10)}
    ab = out["ab"]
    assert ab["scenarios"] == 10 and ab["difference"] == 0.3 and ab["only_b_held"] == 3
    assert ab["rate_a"] == 0.5 and ab["rate_b"] == 0.8
    text = "\n".join(grasp_report.describe_grasps(out))
    assert "b minus a = +30.0%" in text


def test_a_sampled_parameter_is_tabled_by_quartiles() -> None:
    col = np.asarray(np.random.default_rng(0).uniform(0.1, 0.6, 100).tolist(), dtype=object)
    binned = grasp_report._binned(col)
    labels = sorted(set(binned.tolist()))
    assert len(labels) == 4 and all(20 <= (binned == b).sum() <= 30 for b in labels)
    few = np.asarray([0.1, 0.3, 0.1], dtype=object)
    assert grasp_report._binned(few).tolist() == [0.1, 0.3, 0.1]
