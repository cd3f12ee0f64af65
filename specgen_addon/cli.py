"""Command-line interface: ``python -m specgen_addon <command> [...]``.

Each command lives in its own module exposing ``add_parser(subparsers)``; the parser it returns
sets ``func=run``. Errors a user can cause surface as one line on stderr and a non-zero exit.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from . import __version__
from .errors import SpecGenError

#: Modules (relative to this package) that contribute sub-commands, in help order.
COMMAND_MODULES = [
    "cli_brdf",
    "cli_corpus",
    "cli_eval",
    "cli_model",
    "cli_render",
    "cli_scale",
]

EXIT_USER_ERROR = 2
EXIT_CANCELLED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m specgen_addon",
        description="SpecGen: generate a spectral BRDF from one RGB image of a material sphere, "
                    "and the tools around it (formats, corpus, rendering, training, evaluation).")
    parser.add_argument("--version", action="version", version=f"specgen_addon {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(f"{__package__}.{name}").add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USER_ERROR
    try:
        return int(args.func(args) or 0)
    except SpecGenError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("cancelled: nothing partial was written", file=sys.stderr)
        return EXIT_CANCELLED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
