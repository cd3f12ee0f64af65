"""Load any BRDF file: MERL ``.binary``, RGL ``.bsdf`` and SpecGen tables (``.npz``).

:func:`load_brdf` dispatches on the file's magic bytes (not only its suffix) and returns an
object following the BRDF protocol: ``eval(wi, wo, wavelengths_nm)`` / ``eval_rgb(wi, wo)``;
:func:`tabulate_file` puts any of them on the MERL grid.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from specgen_addon.brdf.table import BRDFTable
from specgen_addon.common.errors import BRDFFormatError
from specgen_addon.brdf.formats.merl import read_merl
from specgen_addon.brdf.formats.rgl import read_rgl, tabulate_rgl

RGL_MAGIC = b"tensor_file\0"
NPZ_MAGIC = b"PK\x03\x04"


def detect_format(path: str | Path) -> str:
    """Return ``"rgl"``, ``"merl"`` or ``"table"``; raise :class:`BRDFFormatError` otherwise."""
    path = Path(path)
    if path.is_dir():
        raise BRDFFormatError(path, "is a folder, expected a BRDF file")
    if not path.exists():
        raise BRDFFormatError(path, "no such file")
    if not path.is_file():  # a device or a named pipe
        raise BRDFFormatError(path, "is not a regular file, expected a BRDF file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(12)
    except OSError as exc:
        raise BRDFFormatError(path, f"cannot read file ({exc.strerror or exc})") from None
    if head.startswith(RGL_MAGIC[:11]):
        return "rgl"
    if head.startswith(NPZ_MAGIC):
        return "table"
    if path.suffix.lower() == ".binary" or head[:12] == b"Z\x00\x00\x00Z\x00\x00\x00\xb4\x00\x00\x00":
        return "merl"
    raise BRDFFormatError(path, "unknown BRDF format (expected RGL .bsdf, MERL .binary or SpecGen .npz)")


def load_brdf(path: str | Path):
    """Load any supported BRDF file as an evaluable object (table or RGL BSDF)."""
    kind = detect_format(path)
    if kind == "rgl":
        return read_rgl(path)
    if kind == "merl":
        return read_merl(path).to_table(source=str(path))
    return BRDFTable.load(path)


def tabulate_file(path: Path, wavelengths_nm: np.ndarray, progress=None) -> BRDFTable:
    """Load any BRDF file and return it on the MERL grid (spectral files at ``wavelengths_nm``)."""
    brdf = load_brdf(path)
    if isinstance(brdf, BRDFTable):
        return brdf
    return tabulate_rgl(brdf, wavelengths_nm if brdf.is_spectral else None, progress=progress)
