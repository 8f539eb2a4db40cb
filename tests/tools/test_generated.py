"""The one write-or-check loop of every generator (tools/generated.py): it writes only what
changed, and in check mode writes nothing and names what is stale with the command to run."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tools.generated import write_or_check


def test_writes_only_the_outputs_that_changed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    same, other, new = tmp_path / "same.h", tmp_path / "other.h", tmp_path / "sub" / "new.h"
    same.write_text("kept\n")
    other.write_text("old\n")
    os.utime(same, (1, 1))
    outputs = {same: "kept\n", other: "fresh\n", new: "made\n"}
    assert write_or_check(outputs, check=False, tool="gen", command="x", root=tmp_path) == 0
    assert same.stat().st_mtime == 1  # not rewritten: make sees nothing new
    assert other.read_text() == "fresh\n" and new.read_text() == "made\n"
    out = capsys.readouterr().out
    assert "gen: wrote other.h" in out and "gen: wrote sub/new.h" in out and "same" not in out


def test_check_writes_nothing_and_names_what_is_stale(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fresh, stale, missing = tmp_path / "a.h", tmp_path / "b.h", tmp_path / "c.h"
    fresh.write_text("a\n")
    stale.write_text("old\n")
    outputs = {fresh: "a\n", stale: "new\n", missing: "c\n"}
    code = write_or_check(outputs, check=True, tool="gen", command="make it", root=tmp_path)
    assert code == 1
    assert stale.read_text() == "old\n" and not missing.exists()
    assert capsys.readouterr().err == "gen: stale (run `make it`): b.h, c.h\n"
    assert write_or_check({fresh: "a\n"}, check=True, tool="gen", command="x") == 0
