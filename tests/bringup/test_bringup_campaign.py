"""``make bringup-campaign``'s bookkeeping, without a board: what counts as missed and false,
the table's totals, and a second sitting resuming from the results file."""

from __future__ import annotations

import json
from pathlib import Path

from tools.bringup_campaign import EXPECTED, _done, table
from utrf.bringup.findings import KINDS as FINDINGS
from utrf.emulator.build_faults import KINDS as FAULTS


def _row(seed: int, missed: list[str], false: list[str], ok: bool | None) -> dict[str, object]:
    demo = None
    if ok is not None:
        demo = {
            "ok": ok,
            "tracking_deg": {"index": {"rms": 0.4, "worst": 3.5 if not ok else 1.2}},
            "settled": {"1:open": True},
        }
    return {
        "seed": seed,
        "n_faults": 3,
        "faults": ["slack:1"],
        "missed": missed,
        "false": false,
        "fixable": ok is not None,
        "saved": ok is not None,
        "board_time_s": 90.0 + seed,
        "demo": demo,
    }


def test_every_fault_kind_has_a_finding_that_names_it() -> None:
    assert set(EXPECTED) == set(FAULTS)
    assert set(EXPECTED.values()) <= set(FINDINGS)


def test_the_table_counts_misses_false_diagnoses_and_the_demo() -> None:
    rows = [
        _row(0, ["slack@1"], [], None),
        _row(1, [], ["friction@2"], True),
        _row(2, [], [], False),
    ]
    text = table(rows, "cmd", 120.0, 2, ("<!-- B -->", "<!-- E -->"))
    assert text.startswith("<!-- B -->") and text.endswith("<!-- E -->")
    assert "3 builds: 1 faults missed, 1 false diagnoses" in text
    assert "1 of the 2 fixable builds met the demo's tracking goal" in text
    assert "92.0 s of board time" in text
    assert "FAIL (0.40 / 3.50)" in text


def test_a_second_sitting_resumes_from_the_results(tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl"
    other = {**_row(5, [], [], True), "n_faults": 2}  # another campaign's: not reused
    path.write_text("".join(json.dumps(r) + "\n" for r in [_row(3, [], [], True), other]))
    assert sorted(_done(path, 3)) == [3]
    assert _done(path, 3, fixable=True) == {}  # the fixable-only campaign's builds differ
    assert _done(tmp_path / "none.jsonl", 3) == {}


def test_fixable_builds_draw_only_fixable_kinds() -> None:
    from utrf.emulator import BuildFaults
    from utrf.emulator.build_faults import FIXABLE_KINDS

    kinds = {
        k for s in range(20) for k, _ in BuildFaults.random(s, 3, kinds=FIXABLE_KINDS).faults()
    }
    assert kinds <= set(FIXABLE_KINDS) and len(kinds) >= 5
