"""Every numeric bound and every up-front check a command runs before expensive work.

One place for the limits (documented in docs/errors.md): the CLI, ``batch.py``, the operators and
the Python API call these checks first, so a bad argument, file, name or folder is refused with
one :class:`~specgen_addon.common.errors.SpecGenError` sentence before any network, bake or render runs.
No bpy, no torch: this runs inside a stock Blender too.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Iterable

import numpy as np

from specgen_addon.common.errors import OutputExistsError, SpecGenError

#: (lowest, highest) accepted value of each numeric setting, by option name.
BOUNDS: dict[str, tuple[float, float]] = {
    "resolution": (8, 4096),        # batch.py / panel render size, pixels per side
    "bands": (1, 128),              # wavelength bands of a table, render or bake
    "samples": (1, 4096),           # Cycles samples per pixel
    "env-samples": (1, 64),         # environment directions per Cycles sample (0 renders black)
    "size": (16, 2048),             # render-input image size, pixels per side
    "limit": (1, 1000),             # evaluate: number of test materials
    "n": (1, 100_000),              # corpus: number of materials
    "variant": (0, 100_000),        # render-input: training lighting variant
    "steps": (1, 10_000_000),       # train: optimiser steps
    "max-minutes": (0.01, 100_000.0),
    "wavelength": (360.0, 1000.0),  # nm, any band centre
    "lookup-resolution": (2, 180),  # φd samples of the baked lookup
    "corpus-index": (0, 99_999),    # render-input MATERIAL given as matNNNN or an index
    "ablation-steps": (1, 10_000_000),
    "budget-minutes": (0.01, 100_000.0),
    "workers": (1, 256),            # corpus --inputs / batch-many: worker processes
}
#: Largest input image accepted, in pixels (width × height), checked from the header.
MAX_IMAGE_PIXELS = 100_000_000
#: Images with a longer side than this are box-downsampled while decoding (bounded memory).
MAX_WORK_SIDE = 2048
#: Largest finite value accepted in a BRDF table (sr⁻¹); above float32 range means overflow.
MAX_BRDF_VALUE = 1e30


def check_number(name: str, value: float | int | None, bounds: tuple[float, float] | None = None,
                 integer: bool = True) -> None:
    """Refuse ``value`` outside ``BOUNDS[name]`` (or ``bounds``); ``None`` (unset) passes."""
    if value is None:
        return
    lo, hi = bounds or BOUNDS[name]
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SpecGenError(f"--{name} must be a number, got {value!r}")
    if integer and float(value) != int(value):
        raise SpecGenError(f"--{name} must be a whole number, got {value}")
    if not math.isfinite(float(value)) or not lo <= value <= hi:
        raise SpecGenError(f"--{name} must be between {_fmt(lo)} and {_fmt(hi)}, got {_fmt(value)}")


def _fmt(x: float) -> str:
    return f"{x:,}" if isinstance(x, (int, np.integer)) else f"{x:g}"


def check_numbers(values: dict[str, float | int | None]) -> None:
    """:func:`check_number` on each ``{option name: value}`` (floats where the bound is a float)."""
    for name, value in values.items():
        check_number(name, value, integer=isinstance(BOUNDS[name][0], int))


def check_wavelength_range(wl_min: float, wl_max: float, bands: int) -> None:
    """Band count and range (nm) of a spectral output, as the CLI and batch.py take them."""
    check_number("bands", bands)
    lo, hi = BOUNDS["wavelength"]
    for wl in (wl_min, wl_max):
        if not (math.isfinite(wl) and lo <= wl <= hi):
            raise SpecGenError(f"wavelengths must lie between {lo:g} and {hi:g} nm, got {wl:g}")
    if bands > 1 and not wl_min < wl_max:
        raise SpecGenError(f"the wavelength range must increase, got {wl_min:g}–{wl_max:g} nm")


def safe_name(name: str, what: str = "name") -> str:
    """A file or datablock name with no path separator, no ``..`` and no control character."""
    bad = (not name or name in (".", "..") or ".." in name or any(s in name for s in ("/", "\\"))
           or os.path.isabs(name) or any(ord(c) < 32 for c in name))
    if bad:
        raise SpecGenError(f"{what} {name!r} must be a plain file name (no folders, no '..')")
    return name


def name_max(folder: str | os.PathLike) -> int:
    """Longest file name (bytes) the file system holding ``folder`` (or its nearest existing
    ancestor) accepts; 255 where it cannot be asked."""
    folder = Path(folder)
    for f in [folder, *folder.parents]:
        if f.is_dir():
            try:
                return int(os.pathconf(f, "PC_NAME_MAX"))
            except (OSError, ValueError, AttributeError):
                break
    return 255


def check_name_length(path: str | os.PathLike) -> Path:
    """Refuse an output whose file name (or a folder name on its way) is longer than the file
    system allows, before any work: the write itself would fail only at its very end."""
    path = Path(path)
    for part in path.parts:
        size = len(os.fsencode(part))
        if part not in (os.sep, "/") and size > name_max(path.parent):
            raise SpecGenError(f"{path}: the name {part[:24]}… is {size} bytes long; this file system "
                               f"allows {name_max(path.parent)} (choose a shorter name)")
    return path


def check_input_file(path: str | os.PathLike, what: str = "input file") -> Path:
    """An existing, readable regular file (a folder or an unreadable file is named as such)."""
    path = Path(path)
    if path.is_dir():
        raise SpecGenError(f"{path}: is a folder, expected a file ({what})")
    if not path.exists():
        raise SpecGenError(f"{path}: {what} not found")
    if not path.is_file():  # a device or a named pipe: reading it could block or never end
        raise SpecGenError(f"{path}: is not a regular file ({what})")
    if not os.access(path, os.R_OK):
        raise SpecGenError(f"{path}: {what} is not readable (permission denied)")
    return path


def check_output_dir(path: str | os.PathLike) -> Path:
    """An output folder that is (or could be made) a writable directory; refuses a file in the way.

    Its missing ancestors are checked for a file in the way too, so a refused command leaves
    nothing behind; :func:`specgen_addon.common.atomic_io.make_output_dir` makes it.
    """
    path = check_name_length(path)
    for parent in [path, *path.parents]:
        if parent.exists():
            if not parent.is_dir():
                raise SpecGenError(f"{path}: cannot be the output folder ({parent} is a file)")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise SpecGenError(f"{path}: folder {parent} is not writable")
            break
    return path


def check_output_file(path: str | os.PathLike, overwrite: bool = False,
                      suffixes: Iterable[str] | None = None) -> Path:
    """An output file whose folder exists and is writable, which is not a folder and which only
    replaces an existing file when ``overwrite``."""
    path = check_name_length(path)
    if suffixes is not None and path.suffix.lower() not in tuple(suffixes):
        raise SpecGenError(f"{path}: output must end in {' or '.join(suffixes)}")
    if path.is_dir():
        raise SpecGenError(f"{path}: is a folder, expected an output file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        in_the_way = next((p for p in [parent, *parent.parents] if p.exists()), None)
        if in_the_way is not None and not in_the_way.is_dir():
            raise SpecGenError(f"{path}: cannot be the output folder ({in_the_way} is a file)")
        raise SpecGenError(f"{path}: output folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise SpecGenError(f"{path}: output folder {parent} is not writable")
    refuse_existing(path, overwrite)
    return path


def refuse_existing(path: str | os.PathLike, overwrite: bool) -> None:
    """Refuse, without ``overwrite``, an output that is there already: a file, or a link, even one
    to a missing file (found before the work, not when the finished file cannot be published)."""
    if not overwrite and os.path.lexists(path):
        dangling = os.path.islink(path) and not os.path.exists(path)
        raise OutputExistsError(f"{path}: already exists{' (a link to a missing file)' if dangling else ''} "
                                "(pass --overwrite to replace it)")


def bad_values(values: np.ndarray, allow_negative: bool = False) -> str | None:
    """What is wrong with BRDF values: counts of NaN, ±Inf, overflowing (> :data:`MAX_BRDF_VALUE`)
    and (unless allowed) negative entries, e.g. ``"12 NaN of 4,374,000 values"``; None if clean.
    Chunked, so a 120 MB table needs no full-size temporaries."""
    flat = np.asarray(values).reshape(-1)
    counts = {"NaN": 0, "infinite": 0, "overflowing": 0, "negative": 0}
    for start in range(0, flat.size, 1 << 22):
        chunk = flat[start:start + (1 << 22)]
        lo, hi = chunk.min(initial=0.0), chunk.max(initial=0.0)      # NaN propagates into both
        if -MAX_BRDF_VALUE <= lo and hi <= MAX_BRDF_VALUE and (allow_negative or lo >= 0):
            continue                                                 # clean: two passes, no masks
        nan = np.isnan(chunk)
        inf = np.isinf(chunk)
        counts["NaN"] += int(nan.sum())
        counts["infinite"] += int(inf.sum())
        finite = chunk[~(nan | inf)]
        counts["overflowing"] += int((np.abs(finite) > MAX_BRDF_VALUE).sum())
        if not allow_negative:
            counts["negative"] += int((finite < 0).sum())
    bad = {k: v for k, v in counts.items() if v}
    if not bad:
        return None
    return ", ".join(f"{v:,} {k}" for k, v in bad.items()) + f" of {flat.size:,} values"


def check_values(values: np.ndarray, source: str, allow_negative: bool = False) -> None:
    """Refuse BRDF values :func:`bad_values` finds fault with, naming ``source`` and the counts."""
    reason = bad_values(values, allow_negative)
    if reason:
        raise SpecGenError(f"{source}: {reason}")
