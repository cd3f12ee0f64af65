"""Named exceptions: every user-facing failure is one of these, with a one-line message."""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from os import PathLike
from typing import Iterator


class SpecGenError(Exception):
    """Base class of all errors SpecGen reports to users (CLI prints ``str(err)`` on one line)."""


class BRDFFormatError(SpecGenError):
    """A BRDF file is truncated, corrupt, of an unknown version, or not of the expected kind."""

    def __init__(self, path: str | PathLike, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


class ImageInputError(SpecGenError):
    """An input image is unreadable, has no sphere, the wrong channels, or non-finite values."""


class WeightsError(SpecGenError):
    """A weights file is missing, corrupt, or does not match the model configuration."""


class OutputExistsError(SpecGenError):
    """An output file exists and overwriting was not requested."""


class OutputBusyError(SpecGenError):
    """An output is being written by another SpecGen process (its lock file is held)."""


class OutputWriteError(SpecGenError):
    """An output could not be written (disk full, quota, I/O error); nothing partial was left."""


class Cancelled(SpecGenError):
    """Long work was cancelled by the user; nothing partial was written."""


@contextlib.contextmanager
def one_line_warnings(verbose: bool = False) -> Iterator[None]:
    """Show SpecGen's own warnings (e.g. "grayscale converted to RGB") as ``warning: <text>``,
    without Python's file name and source line; other libraries' warnings keep their format."""
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    repo = os.path.dirname(package)
    # ours: the package, and the entries a warning may be attributed to (``stacklevel``)
    ours = (package + os.sep, os.path.join(repo, "ops") + os.sep)
    entries = {os.path.join(repo, "batch.py"), os.path.join(repo, "__init__.py")}
    previous = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        where = os.path.abspath(filename)
        if verbose or not (where.startswith(ours) or where in entries):
            return previous(message, category, filename, lineno, file, line)
        print(f"warning: {message}", file=file or sys.stderr)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = previous
