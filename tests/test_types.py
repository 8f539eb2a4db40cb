"""The type checker runs with the suite (issue 12): mypy over host/utrf, configured in
pyproject.toml ([tool.mypy]: strict optionals, untyped bodies checked, unused ignores
reported), and no `# type: ignore` without its reason on the same line."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "host" / "utrf"

# `# type: ignore[code]  # why` -- the code names what is silenced, the comment says why.
_IGNORE = re.compile(r"#\s*type:\s*ignore(?P<rest>.*)$")
_JUSTIFIED = re.compile(r"^\[[\w\-, ]+\]\s+#\s*\S")


def test_mypy_passes_on_the_package() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--no-error-summary"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, f"mypy (config in pyproject.toml):\n{run.stdout}{run.stderr}"


def test_the_configuration_catches_a_wrong_optional_and_an_untyped_body(tmp_path: Path) -> None:
    """The checker is as strict as the suite relies on: these must fail under pyproject.toml."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "def first(xs: list[int]) -> int | None:\n"
        "    return xs[0] if xs else None\n"
        "\n"
        "\n"
        "def double(xs: list[int]) -> int:\n"
        "    return first(xs) * 2\n"  # a wrong Optional
        "\n"
        "\n"
        "def untyped(x):\n"  # no annotations
        "    y: str = 1\n"  # an error inside an untyped body
        "    return x + 1  # type: ignore\n"  # an ignore that silences nothing
    )
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"), str(probe)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    out = run.stdout
    assert run.returncode == 1, out
    for code in ("operator", "no-untyped-def", "assignment", "unused-ignore"):
        assert f"[{code}]" in out, f"mypy missed [{code}]:\n{out}"


def unjustified_ignores(text: str) -> list[int]:
    """Line numbers of `type: ignore` comments lacking an error code and a reason."""
    bad = []
    for number, line in enumerate(text.splitlines(), 1):
        found = _IGNORE.search(line)
        if found and not _JUSTIFIED.match(found["rest"].strip()):
            bad.append(number)
    return bad


def test_the_scan_tells_a_reasoned_ignore_from_a_bare_one() -> None:
    assert unjustified_ignores("x = f()  # type: ignore[arg-type]  # numpy stubs: tuple") == []
    assert unjustified_ignores("x = f()  # type: ignore[arg-type]") == [1]
    assert unjustified_ignores("x = f()  # type: ignore") == [1]
    assert unjustified_ignores("ok = 1\nx = f()  # type:ignore  # why") == [2]


def test_every_type_ignore_says_why() -> None:
    bad = [
        f"{path.relative_to(ROOT)}:{number}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for number in unjustified_ignores(path.read_text(encoding="utf-8"))
    ]
    assert not bad, "`# type: ignore[code]` needs `  # reason` on the same line:\n" + "\n".join(bad)
