"""The layering of the host package, read from its imports: the lower layers import nothing above.

Each guarded subpackage lists the ``utrf`` modules it may import; anything else from ``utrf`` is
an upward (or sideways) import and fails here, naming the file, the line and the import.
Data files are read through ``importlib.resources``, which is not an import and is allowed.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

HOST = Path(__file__).resolve().parents[1] / "host"

# subpackage -> the utrf modules (and their submodules) it may import.
ALLOWED: dict[str, tuple[str, ...]] = {
    "utrf.protocol": ("utrf.protocol",),
    "utrf.models": ("utrf.models",),
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(HOST).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def utrf_imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every ``utrf`` import in ``path``, relative ones resolved, at any depth
    (a late import inside a function counts as much as one at the top)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # ``from utrf import poses`` imports utrf.poses, not utrf.
            if target == "utrf" or (node.level and not node.module):
                found += [(node.lineno, f"{target}.{a.name}") for a in node.names]
            else:
                found.append((node.lineno, target))
    return [(line, mod) for line, mod in found if mod == "utrf" or mod.startswith("utrf.")]


def within(module: str, roots: tuple[str, ...]) -> bool:
    return any(module == r or module.startswith(r + ".") for r in roots)


def violations(package: str, allowed: tuple[str, ...]) -> list[str]:
    folder = HOST.joinpath(*package.split("."))
    return [
        f"{path.relative_to(HOST)}:{line} imports {mod}"
        for path in sorted(folder.rglob("*.py"))
        for line, mod in utrf_imports(path)
        if not within(mod, allowed)
    ]


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_lower_layers_import_nothing_above_them(package: str) -> None:
    assert HOST.joinpath(*package.split(".")).is_dir(), f"{package} is not in {HOST}"
    found = violations(package, ALLOWED[package])
    assert not found, f"{package} may import only {ALLOWED[package]}:\n" + "\n".join(found)


def test_an_upward_import_is_caught(tmp_path: Path) -> None:
    """The scan itself: late, relative and ``from utrf import x`` forms are all seen."""
    pkg = tmp_path / "utrf" / "models"
    pkg.mkdir(parents=True)
    src = pkg / "late.py"
    src.write_text(
        "from . import geometry\n"
        "def f():\n"
        "    from utrf.poses import PoseLibrary\n"
        "    from .. import hand\n"
        "    from utrf import cli\n"
        "    import utrf.protocol.link\n",
        encoding="utf-8",
    )
    global HOST
    saved, HOST = HOST, tmp_path
    try:
        mods = [m for _, m in utrf_imports(src)]
    finally:
        HOST = saved
    assert mods == [
        "utrf.models.geometry",
        "utrf.poses",
        "utrf.hand",
        "utrf.cli",
        "utrf.protocol.link",
    ]
    assert [m for m in mods if not within(m, ALLOWED["utrf.models"])] == mods[1:]
