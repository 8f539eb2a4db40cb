"""The ``utrf`` command line.

Every module in this package that defines ``register(subparsers)`` adds its subcommands;
a subcommand's handler takes the parsed arguments and returns an exit code. Adding a
command is adding a module, so areas of the project do not edit a shared list.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from utrf import __version__


def error(command: str, text: object) -> None:
    """Every command's one line on stderr for a failure: ``utrf COMMAND: error: TEXT``."""
    print(f"utrf {command}: error: {text}", file=sys.stderr)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="utrf",
        description="UTRF-RoboHand: models, emulated board, poses and tools. "
        "APIs and --json output use SI units (m, rad, N, s); tables for people show "
        "mm and degrees and say so.",
    )
    parser.add_argument("--version", action="version", version=f"utrf {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handler = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return 2
    try:
        return int(handler(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
