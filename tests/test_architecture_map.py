"""docs/architecture.md's map matches the tree: every path its Layout table names exists, and
every module of the package is named there or lies in a folder named there. The installed
package imports nothing from the repository's maintenance code (tools/) or its tests."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "host" / "utrf"
MAP = REPO / "docs" / "architecture.md"
# a file or folder name in the description column: has a folder part, or a file's ending
NAME = re.compile(r"^[\w.*/-]+(/|\.(py|toml|md|mk|h|cpp|c|sh|csv|json))$|^[\w.*-]+/[\w.*/-]+$")


def layout_rows() -> list[tuple[list[str], list[str]]]:
    """(paths of the first column, code spans of the second) for each row of the Layout table."""
    text = MAP.read_text(encoding="utf-8")
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        first, rest = line[1:].split("|", 1)
        rows.append((re.findall(r"`([^`]+)`", first), re.findall(r"`([^`]+)`", rest)))
    return rows


def test_every_path_the_map_names_exists() -> None:
    rows = layout_rows()
    assert len(rows) > 10, "docs/architecture.md lost its Layout table"
    missing = []
    for paths, spans in rows:
        for path in paths:
            if "<" not in path and not (REPO / path).exists():  # tests/<area>/: a pattern
                missing.append(path)
        where = [REPO / p for p in paths if (REPO / p).is_dir()] or [REPO]
        for span in spans:
            if not NAME.match(span):
                continue  # a module name, a command, a word
            if not any((REPO / span).exists() or any(w.glob(f"**/{span}")) for w in where):
                missing.append(f"{span} (in the row of {', '.join(paths)})")
    assert not missing, f"docs/architecture.md names what is not in the tree: {missing}"


def test_every_package_module_is_on_the_map() -> None:
    named = {p.rstrip("/") for paths, _ in layout_rows() for p in paths}
    unmapped = []
    for module in sorted(PACKAGE.rglob("*.py")):
        rel = module.relative_to(REPO)
        # named itself, or a folder of it below host/utrf (host/utrf/ itself covers nothing)
        covers = [rel, *rel.parents]
        if not any(str(c) in named for c in covers if c != PACKAGE.relative_to(REPO)):
            unmapped.append(str(rel))
    assert not unmapped, f"add these to docs/architecture.md's Layout table: {unmapped}"


def test_the_package_imports_no_repository_code() -> None:
    bad = []
    for module in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(module.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            for name in names:
                if name.split(".")[0] in {"tools", "tests", "protocol"}:
                    bad.append(f"{module.relative_to(REPO)}: {name}")
    assert not bad, f"the installed package cannot import these: {bad}"
