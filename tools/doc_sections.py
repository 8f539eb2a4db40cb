"""A doc writer writes its own section of a Markdown file (``docs/benchmarks.md``,
``docs/reliability.md``, ``hil/README.md``) and leaves the rest alone.

A section is found by its markers (``<!-- BEGIN x -->`` … ``<!-- END x -->``, both part of
the section's text), or, without an end marker, by its heading: from that line up to the next
section, marked or not (a ``## `` heading or a ``<!-- `` marker line). It is replaced where it
stands, or appended to the file when it is not there yet.

    write_section(Path("docs/benchmarks.md"), section, BEGIN, END)
    write_section(Path("docs/benchmarks.md"), "## Models\\n\\n...", "## Models")

The file is written through :func:`tools.generated.write_or_check`, so a writer can also check
that the committed section is current (``updated`` gives the file's text with it).
"""

from __future__ import annotations

import platform
import re
from pathlib import Path

from tools.generated import write_or_check

NEW_FILE = "# Benchmarks\n"
# where a section without an end marker ends: the next heading or marker line
_NEXT_SECTION = re.compile(r"^(## |<!-- )", re.M)


def cpu_name() -> str:
    """The processor's model, for the line that says where figures were measured."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def replace_section(text: str, section: str, begin: str, end: str | None = None) -> str:
    """``text`` with the section that starts at ``begin`` (and ends with ``end``, or else at
    the next section) replaced by ``section``, or with ``section`` appended."""
    section = section.rstrip("\n")
    span = _find(text, begin, end)
    if span is None:
        return text.rstrip("\n") + "\n\n" + section + "\n"
    start, stop = span
    return text[:start] + section + text[stop:]


def updated(path: Path, section: str, begin: str, end: str | None = None) -> str:
    """The text of the Markdown file at ``path`` with ``section`` in it (see
    :func:`replace_section`); a missing file starts as ``# Benchmarks``."""
    text = path.read_text(encoding="utf-8") if path.exists() else NEW_FILE
    return replace_section(text, section, begin, end)


def write_section(path: Path, section: str, begin: str, end: str | None = None) -> None:
    """Write ``section`` into the Markdown file at ``path`` (see :func:`updated`)."""
    write_or_check(
        {path: updated(path, section, begin, end)},
        check=False,
        tool="doc_sections",
        command=f"the command that writes {path.name}",
    )


def _find(text: str, begin: str, end: str | None) -> tuple[int, int] | None:
    if end is not None:
        start = text.find(begin)
        if start < 0:
            return None
        stop = text.find(end, start + len(begin))
        return None if stop < 0 else (start, stop + len(end))
    heading = re.search(rf"^{re.escape(begin)}$", text, re.M)
    if heading is None:
        return None
    following = _NEXT_SECTION.search(text, heading.end())
    stop = len(text) if following is None else following.start()
    return heading.start(), len(text[:stop].rstrip("\n"))
