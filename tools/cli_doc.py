"""docs/hand.md's table of `utrf` commands, written from the command's own parser (what
`utrf --help` and each `utrf COMMAND --help` print), so the two cannot differ.

    python -m tools.cli_doc           # rewrite the section (part of `make generate`)
    python -m tools.cli_doc --check   # exit 1 when the committed section is stale
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.doc_sections import updated
from tools.generated import write_or_check
from utrf.cli import build_parser

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "hand.md"
BEGIN = "<!-- BEGIN utrf-help: written by `python -m tools.cli_doc` from `utrf --help` -->"
END = "<!-- END utrf-help -->"
COMMAND = "python -m tools.cli_doc"


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """(name, help, parser) of a parser's subcommands, in the order `--help` lists them."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            return [(name, helps.get(name, ""), p) for name, p in action.choices.items()]
    return []


def _usage(parser: argparse.ArgumentParser) -> str:
    text = " ".join(parser.format_usage().split())
    return text.removeprefix("usage: ").replace(" [-h]", "")


def render() -> str:
    rows = ["| command | what it does |", "|---|---|"]

    def add(parser: argparse.ArgumentParser, what: str) -> None:
        nested = _subcommands(parser)
        if not nested:
            usage = _usage(parser).replace("|", "\\|")
            rows.append(f"| `{usage}` | {what.replace('|', '/')} |")
        for _, help_, sub in nested:
            add(sub, help_)

    for _, help_, sub in _subcommands(build_parser()):
        add(sub, help_)
    return "\n".join([BEGIN, *rows, END]) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=COMMAND, description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--check", action="store_true", help="fail if the section is stale")
    args = parser.parse_args(argv)
    text = updated(DOC, render(), BEGIN, END)
    return write_or_check({DOC: text}, check=args.check, tool="cli_doc", command=COMMAND, root=REPO)


if __name__ == "__main__":
    raise SystemExit(main())
