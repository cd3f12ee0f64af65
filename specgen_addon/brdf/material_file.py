"""The compact material file: a BRDF table stored in a few megabytes instead of 122.

A full table (90 × 90 × 180 × 21 float32) is 122 MB, while the BRDF it holds is smooth along
every axis. The compact file keeps every value to a fixed *relative* precision: the natural log
of each value is rounded to a multiple of :data:`LOG_STEP` (1/256: a value is kept within
±0.2 %), then each code is replaced by its difference to the previous wavelength and that by its
difference to the previous φd sample (mostly 0 and ±1), and the result is deflated (zlib). Zero
(and negative, which a BRDF lookup clamps to zero anyway) values are kept as exact zeros; values
below :data:`FLOOR` sr⁻¹ are raised to it.

It is the same ``.npz`` container as the full table, with header format
``specgen-brdf-compact``: :meth:`specgen_addon.brdf.table.BRDFTable.load` reads either kind, so a
compact file can go wherever a table went. docs/formats.md gives its measured size, rebuild time
and the rendered difference to the full table.
"""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import BRDFFormatError
from specgen_addon.common.atomic_io import atomic_write, write_npz
#: Header format of the compact material file.
COMPACT_FORMAT = "specgen-brdf-compact"
COMPACT_VERSION = 1
#: Rounding step of ln(f_r): values are kept to within ±(e^(step/2) − 1) ≈ ±0.2 %.
LOG_STEP = 1.0 / 256.0
#: Smallest non-zero value kept (sr⁻¹); smaller ones are raised to it.
FLOOR = 1e-9
#: The code of an exact zero (below every other code).
_ZERO = int(np.floor(np.log(FLOOR) / LOG_STEP)) - 1
#: Deflate level: 4 writes a 21-band material 2–3× faster than 6 for an 8–11 % larger file
#: (docs/formats.md); any level reads back the same.
ZLIB_LEVEL = 4


def encode(values: np.ndarray) -> tuple[bytes, str]:
    """The deflated, twice-differenced log codes of ``values`` (θh, θd, φd, C) and their dtype."""
    v = np.asarray(values, dtype=np.float32)
    logs = np.maximum(v, np.float32(FLOOR))
    np.log(logs, out=logs)
    logs *= np.float32(1.0 / LOG_STEP)
    codes = np.rint(logs).astype(np.int32)
    codes[~(v > 0)] = _ZERO
    d = _difference(_difference(codes, axis=3), axis=2)
    small = int(np.abs(d).max(initial=0)) < 2 ** 15
    raw = np.ascontiguousarray(d.astype(np.int16 if small else np.int32))
    return zlib.compress(raw.tobytes(), ZLIB_LEVEL), str(raw.dtype)


def _difference(a: np.ndarray, axis: int) -> np.ndarray:
    """``np.diff(a, axis=axis, prepend=0)`` without its concatenated copy (ten times faster along
    the short last axis): the first entry kept, every other one minus its predecessor."""
    out = np.empty_like(a)
    src, dst = np.moveaxis(a, axis, 0), np.moveaxis(out, axis, 0)      # views, the axis first
    dst[0] = src[0]
    np.subtract(src[1:], src[:-1], out=dst[1:])
    return out


def decode(payload: bytes, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    """The float32 values that :func:`encode` stored."""
    d = np.frombuffer(zlib.decompress(payload), dtype=np.dtype(dtype)).reshape(shape)
    codes = np.cumsum(d, axis=2, dtype=np.int32)
    np.cumsum(codes, axis=3, dtype=np.int32, out=codes)
    zero = codes == _ZERO
    out = codes.astype(np.float32)
    out *= np.float32(LOG_STEP)
    np.exp(out, out=out)
    out[zero] = 0.0
    return out


def save_compact(table, path: str | Path, overwrite: bool = False) -> Path:
    """Write ``table`` (a :class:`~specgen_addon.brdf.table.BRDFTable`) as a compact file, atomically."""
    path = Path(path)
    payload, dtype = encode(table.values)
    header = {"format": COMPACT_FORMAT, "version": COMPACT_VERSION, "channels": list(table.channels),
              "metadata": table.metadata, "shape": list(table.values.shape), "dtype": dtype,
              "log_step": LOG_STEP, "floor": FLOOR}
    with atomic_write(path, overwrite=overwrite) as tmp:
        write_npz(tmp, codes=np.frombuffer(payload, dtype=np.uint8),
                  wavelengths=(table.wavelengths if table.is_spectral else np.zeros(0)),
                  header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    return path


def load_compact(path: Path, header: dict, z) -> tuple[np.ndarray, np.ndarray]:
    """(values, wavelengths) of an open compact file ``z`` whose header was read."""
    if header.get("version") != COMPACT_VERSION:
        raise BRDFFormatError(path, f"unsupported compact material version {header.get('version')}")
    if header.get("log_step") != LOG_STEP or header.get("floor") != FLOOR:
        raise BRDFFormatError(path, "compact material written with another precision")
    shape = tuple(int(n) for n in header.get("shape", ()))
    if len(shape) != 4 or header.get("dtype") not in ("int16", "int32"):
        raise BRDFFormatError(path, "compact material with a bad shape or code type")
    try:
        values = decode(z["codes"].tobytes(), header["dtype"], shape)
    except (zlib.error, ValueError) as exc:
        raise BRDFFormatError(path, f"damaged compact material ({exc})") from None
    return values, z["wavelengths"]
