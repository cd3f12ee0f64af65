"""Named exceptions: every user-facing failure is one of these, with a one-line message."""

from __future__ import annotations

from os import PathLike


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


class Cancelled(SpecGenError):
    """Long work was cancelled by the user; nothing partial was written."""
