"""Command-line interface: ``python -m specgen_addon <command> [...]``.

Each command lives in its own module exposing ``add_parser(subparsers)``; the parser it returns
sets ``func=run``. Errors a user can cause surface as one line on stderr and a non-zero exit.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import Callable, Sequence

from specgen_addon import __version__
from specgen_addon.common.errors import SpecGenError, one_line_warnings
from specgen_addon.common.atomic_io import (OutputLock, created_since, ledger_mark, make_lock_folders,
                                            remove_created, replacements_kept)
from specgen_addon.common.interrupts import (EXIT_ERROR, OutputGuard, as_interrupted, on_hard_stop,
                                             print_traceback_if, raise_if_stopped, stop_on_signals)
from specgen_addon.photo.photo_lighting import attach_signed_values
from specgen_addon.scale.preflight import check_command, output_folders

#: Modules (relative to this package) that contribute sub-commands, in help order.
COMMAND_MODULES = [
    "brdf",
    "corpus",
    "evaluate",
    "model",
    "render",
    "scale",
]

EXIT_USER_ERROR = 2
EXIT_CANCELLED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m specgen_addon",
        description="SpecGen: generate a spectral BRDF from one RGB image of a material sphere, "
                    "and the tools around it (formats, corpus, rendering, training, evaluation).")
    parser.add_argument("--version", action="version", version=f"specgen_addon {__version__}")
    parser.add_argument("--verbose", action="store_true",
                        help="print the traceback of an error after its one-line message")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(f"{__package__}.{name}").add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(attach_signed_values(sys.argv[1:] if argv is None else argv))
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USER_ERROR
    # a stopped training run keeps its last checkpoint (named in the message) for --resume
    keep = [Path(args.out) / n for n in ("checkpoint.pt", "history.csv")] if args.command == "train" and args.out else []
    return run_guarded(args.command, lambda: _run(args), folders_of(args), args.verbose, keep)


def _run(args: argparse.Namespace) -> int:
    check_command(args)  # every argument, file, folder and size, before any work
    return int(args.func(args) or 0)


def folders_of(args: argparse.Namespace):
    return output_folders(args)


def run_guarded(what: str | Callable[[], str], work, outputs=([], []), verbose: bool = False,
                keep: Sequence[str] = (), prog: str = "error") -> int:
    """Run ``work()`` with SIGINT/SIGTERM as clean stops and new outputs removed on failure.

    Returns the exit status: 0, 2 for an error (one line on stderr), 130/143 for SIGINT/SIGTERM
    (one line saying what was stopped and what, if anything, was left).
    """
    folders, files = outputs
    guard = OutputGuard(folders, keep=keep)
    made = make_lock_folders(folders)  # a new output folder's parents: its lock goes beside it
    lock = OutputLock([*folders, *files])  # a second command on these outputs is refused
    mark = ledger_mark()

    def remove_new_files() -> None:  # only the files this process made (by identity)
        remove_created(created_since(mark, files))

    def stopped(signal_name: str) -> str:
        return f"cancelled: {what() if callable(what) else what} stopped by {signal_name}; " \
               f"{guard.left_behind()}"

    try:
        with stop_on_signals(stopped), on_hard_stop(lambda: remove_created(made)), lock, \
                on_hard_stop(lock.release), replacements_kept(), on_hard_stop(remove_new_files), \
                one_line_warnings(verbose):
            try:
                with guard:
                    code = int(work() or 0)
                    raise_if_stopped()  # a signal deferred inside Blender's own code
                    return code
            except Exception:
                # an error after a stop was asked for is the stop's doing (a system call it cut
                # short inside Blender's code, say): report the stop, not the error
                raise_if_stopped()
                raise
            finally:
                if sys.exc_info()[0] is not None:  # failed or stopped: remove new single outputs
                    remove_new_files()
    except KeyboardInterrupt as exc:
        stop = as_interrupted(exc)
        print(stopped(stop.signal_name), file=sys.stderr)
        return stop.exit_code
    except SpecGenError as exc:
        print_traceback_if(verbose, exc)
        print(f"{prog}: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except MemoryError as exc:
        what = what() if callable(what) else what
        print_traceback_if(verbose, exc)
        print(f"{prog}: {what}: out of memory (lower the sizes; see docs/errors.md)", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        print_traceback_if(verbose, exc)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"{prog}: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # a bug: one line, the traceback only with --verbose
        what = what() if callable(what) else what
        print_traceback_if(verbose, exc)
        print(f"{prog}: internal error in {what}: {type(exc).__name__}: {exc} "
              "(rerun with --verbose for the traceback)", file=sys.stderr)
        return EXIT_ERROR
    finally:
        remove_created(made)  # the folders made to hold a lock, when nothing else went in


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
