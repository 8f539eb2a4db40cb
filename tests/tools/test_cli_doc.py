"""docs/hand.md's table of `utrf` commands is what `utrf --help` says (tools/cli_doc.py)."""

from __future__ import annotations

from tools import cli_doc
from utrf.cli import build_parser


def test_the_command_table_in_docs_hand_md_is_current() -> None:
    assert cli_doc.main(["--check"]) == 0, "run `python -m tools.cli_doc` and commit docs/hand.md"


def test_every_command_of_utrf_help_has_a_row() -> None:
    text = cli_doc.render()
    top = cli_doc._subcommands(build_parser())
    assert top
    for name, _, parser in top:
        nested = cli_doc._subcommands(parser)
        for sub in [f"{name} {n}" for n, _, _ in nested] or [name]:
            assert f"| `utrf {sub} " in text or f"| `utrf {sub}`" in text, sub
