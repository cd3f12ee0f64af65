"""How the operators tell the user about errors: one sentence in the report, the traceback only on
the console and only when asked (Blender's ``--debug`` / ``bpy.app.debug``, or SPECGEN_VERBOSE=1).

Also the up-front checks of the panel's settings (bounds from :mod:`specgen_addon.common.limits`), so an
operator refuses bad settings before it starts a network run or a render.
"""

from __future__ import annotations

import os
import sys
import traceback

import bpy

from specgen_addon.common import limits
from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.common.interrupts import Interrupted


def debug_enabled() -> bool:
    """Tracebacks go to the console when Blender runs with --debug or SPECGEN_VERBOSE is set."""
    return bool(bpy.app.debug) or os.environ.get("SPECGEN_VERBOSE", "") not in ("", "0")


def error_sentence(exc: BaseException, doing: str = "SpecGen") -> str:
    """One line for ``self.report``: the error's own sentence, never a traceback."""
    if isinstance(exc, (Cancelled, KeyboardInterrupt)):
        how = f" by {exc.signal_name}" if isinstance(exc, Interrupted) else ""
        return f"{doing} cancelled{how}; nothing partial was left"
    if isinstance(exc, SpecGenError):
        text = str(exc)
    elif isinstance(exc, OSError):
        text = f"{exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}"
    elif isinstance(exc, MemoryError):
        text = f"{doing} ran out of memory (lower the resolution, bands or lookup size)"
    else:
        text = f"{doing} failed unexpectedly ({type(exc).__name__}: {exc})"
    first = text.strip().splitlines()[0] if text.strip() else type(exc).__name__
    return first if first.startswith("SpecGen") else f"SpecGen: {first}"


def report_exception(op, exc: BaseException, doing: str = "SpecGen") -> set[str]:
    """``op.report`` one sentence (a warning for a cancel), traceback on the console in debug mode;
    returns ``{"CANCELLED"}`` for the operator to return."""
    cancelled = isinstance(exc, (Cancelled, KeyboardInterrupt))
    if debug_enabled() and not cancelled:
        traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
    op.report({"WARNING" if cancelled else "ERROR"}, error_sentence(exc, doing))
    return {"CANCELLED"}


def check_generate_settings(s) -> None:
    """Bands and wavelength range of the panel (``scene.specgen``) within their limits."""
    limits.check_wavelength_range(s.wl_min, s.wl_max, s.bands)


def check_render_settings(s, filename: str) -> None:
    """Render settings of the panel and the output file name (plain name ending in .exr)."""
    limits.check_numbers({"samples": s.samples, "resolution": s.resolution,
                          "env-samples": s.env_samples})
    limits.safe_name(filename, "output file name")
    if not filename.lower().endswith(".exr"):
        raise SpecGenError(f"output file name {filename!r} must end in .exr")
