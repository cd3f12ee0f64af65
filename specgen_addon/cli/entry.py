"""The command line's entry point (``specgen``, ``python -m specgen_addon``): loads the commands
and runs one, so that a Ctrl-C while the program is still loading (its imports take a second or
more) ends it as one during the work does: one line and exit 130, no traceback, nothing written."""

from __future__ import annotations

import sys

#: Exit status of a command stopped by SIGINT (128 + 2), as :mod:`specgen_addon.common.interrupts` gives.
EXIT_SIGINT = 130


def main() -> int:
    try:
        from specgen_addon.cli.app import main as run_command

        return run_command()
    except KeyboardInterrupt:   # before the command's own clean stop was in place: nothing written yet
        print("cancelled: specgen stopped by SIGINT while starting; nothing was written", file=sys.stderr)
        return EXIT_SIGINT
