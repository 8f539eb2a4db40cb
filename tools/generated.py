"""Write generated files, or check that the committed ones are current: the one loop every
generator uses (protocol/generate.py, protocol/make_vectors.py, tools.kinematics_table, the
doc writers).

    sys.exit(write_or_check({path: text, ...}, check=args.check, tool="generate",
                            command="python -m protocol.generate"))

A file is rewritten only when its text changes, so an unchanged output keeps its time stamp
(make does not rebuild what depends on it). Standard library only: protocol/generate.py runs
before the ``utrf`` package is installed.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path


def stale(outputs: Mapping[Path, str]) -> list[Path]:
    """The outputs whose file is missing or holds other text."""
    return [
        path
        for path, text in outputs.items()
        if not path.exists() or path.read_text(encoding="utf-8") != text
    ]


def write_or_check(
    outputs: Mapping[Path, str],
    *,
    check: bool,
    tool: str,
    command: str,
    root: Path | None = None,
) -> int:
    """Write each stale output (0), or with ``check`` write nothing and name the stale ones
    on stderr with the command that regenerates them (1 if any). Paths are shown relative to
    ``root`` (default: the working directory)."""
    changed = stale(outputs)
    base = (root or Path.cwd()).resolve()

    def shown(path: Path) -> str:
        try:
            return str(path.resolve().relative_to(base))
        except ValueError:
            return str(path)

    if check:
        if changed:
            names = ", ".join(shown(p) for p in changed)
            print(f"{tool}: stale (run `{command}`): {names}", file=sys.stderr)
            return 1
        return 0
    for path in changed:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(outputs[path], encoding="utf-8")
        print(f"{tool}: wrote {shown(path)}")
    return 0
