"""The benchmarks' sections of docs/benchmarks.md: each replaced where it stands, or appended,
and nothing else touched."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tools.doc_sections import replace_section, write_section

DOC = Path(__file__).resolve().parents[2] / "docs" / "benchmarks.md"
MARKED = re.compile(r"^(<!-- BEGIN (\w+) .*? -->)\n.*?^(<!-- END \2 -->)$", re.S | re.M)


def test_every_marked_section_of_the_doc_is_replaced_in_place() -> None:
    text = DOC.read_text(encoding="utf-8")
    sections = list(MARKED.finditer(text))
    assert {m.group(2) for m in sections} >= {"protocol", "firmware", "emulator", "client"}
    for found in sections:
        begin, end = found.group(1), found.group(3)
        assert replace_section(text, found.group(0), begin, end) == text  # same text: no change
        new = f"{begin}\n## Fresh\n\nfigures\n{end}"
        out = replace_section(text, new + "\n", begin, end)  # a trailing newline is not doubled
        assert out == text[: found.start()] + new + text[found.end() :]


def test_the_models_section_ends_at_the_next_marker_or_heading() -> None:
    text = DOC.read_text(encoding="utf-8")
    out = replace_section(text, "## Models\n\nfresh figures\n", "## Models")
    head, tail = text.split("## Models", 1)
    after = tail[tail.index("<!-- BEGIN firmware") :]
    assert out == head + "## Models\n\nfresh figures\n\n" + after  # the firmware marker stays
    plain = "# B\n\n## Firmware\n\nkeep\n\n## Models\n\nold\n\n\n## Protocol\n\nkeep too\n"
    assert replace_section(plain, "## Models\n\nnew", "## Models") == plain.replace("old", "new")
    last = "# B\n\n## Models\n\nold\nlines\n"
    assert replace_section(last, "## Models\n\nnew\n", "## Models") == "# B\n\n## Models\n\nnew\n"


def test_a_missing_section_is_appended() -> None:
    text = "# Benchmarks\n\n## Protocol\n\nkeep\n\n\n"
    expected = "# Benchmarks\n\n## Protocol\n\nkeep\n\n<!-- BEGIN x -->\nnew\n<!-- END x -->\n"
    section = "<!-- BEGIN x -->\nnew\n<!-- END x -->"
    assert replace_section(text, section, "<!-- BEGIN x -->", "<!-- END x -->") == expected
    # a begin marker without its end is not a section: nothing after it is lost
    broken = "# B\n\n<!-- BEGIN x -->\nhalf\n\n## Other\n\nkeep\n"
    out = replace_section(broken, section, "<!-- BEGIN x -->", "<!-- END x -->")
    assert out == broken + "\n" + section + "\n"
    assert replace_section("# B\n", "## Models\n\nm\n", "## Models") == "# B\n\n## Models\n\nm\n"


@pytest.mark.parametrize("end", ["<!-- END x -->", None])
def test_write_section_creates_then_updates_the_file(tmp_path: Path, end: str | None) -> None:
    path = tmp_path / "docs" / "benchmarks.md"
    begin = "<!-- BEGIN x -->" if end else "## X"
    first = f"{begin}\n\nµs: 1\n{end or ''}".rstrip("\n")
    write_section(path, first, begin, end)
    assert path.read_text(encoding="utf-8") == f"# Benchmarks\n\n{first}\n"
    second = first.replace("1", "2")
    write_section(path, second, begin, end)
    assert path.read_text(encoding="utf-8") == f"# Benchmarks\n\n{second}\n"
