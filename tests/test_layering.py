"""The package's layers, read from the imports (issue 12): the protocol and the models are
the bottom of `utrf` and import nothing above them, so either can be used, tested and
reasoned about on its own."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "host" / "utrf"

# layer -> the utrf modules it may import (itself always)
ALLOWED = {
    "utrf.protocol": ("utrf.protocol",),
    "utrf.models": ("utrf.models",),
}


def utrf_imports(path: Path, package: Path = PACKAGE) -> list[tuple[int, str]]:
    """Every `utrf...` module a source file imports, at any depth (late imports too)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.startswith("utrf")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the importing module's package
                parts = ["utrf", *path.relative_to(package).with_suffix("").parts]
                base = ".".join(parts[: -node.level])
                found.append((node.lineno, f"{base}.{node.module}" if node.module else base))
            elif node.module and node.module.startswith("utrf"):
                found.append((node.lineno, node.module))
    return sorted(found)


def test_the_scan_sees_late_and_relative_imports(tmp_path: Path) -> None:
    package = tmp_path / "utrf"
    probe = package / "models" / "probe.py"
    probe.parent.mkdir(parents=True)
    probe.write_text(
        "import numpy\nfrom . import geometry\nfrom ..hand import Hand\n"
        "def f():\n    from utrf.poses import X\n"
    )
    assert utrf_imports(probe, package) == [
        (2, "utrf.models"),
        (3, "utrf.hand"),
        (5, "utrf.poses"),
    ]


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_lower_layers_import_nothing_above_them(layer: str) -> None:
    folder = PACKAGE.joinpath(*layer.split(".")[1:])
    allowed = ALLOWED[layer]
    bad = [
        f"{path.relative_to(PACKAGE.parent)}:{line} imports {name}"
        for path in sorted(folder.rglob("*.py"))
        for line, name in utrf_imports(path)
        if not name.startswith(allowed)
    ]
    assert not bad, f"{layer} may import only {allowed}:\n" + "\n".join(bad)
