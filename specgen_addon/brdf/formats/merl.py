"""MERL ``.binary`` isotropic BRDFs (Matusik, Pfister, Brand, McMillan 2003).

Layout: three int32 dims ``(90, 90, 180)``, then ``3·90·90·180`` float64, planar (all R, then G,
then B), each block ordered ``[θh][θd][φd]``. Stored values are scaled: R × 1/1500,
G × 1.15/1500, B × 1.66/1500 give ``f_r`` in sr⁻¹. Negative entries mark invalid measurements;
they are masked (set to zero in tables, counted in metadata) rather than propagated.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import BRDFFormatError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.common.limits import bad_values
from specgen_addon.brdf.table import GRID_SHAPE, BRDFTable

#: Per-channel factors from stored numbers to f_r (sr⁻¹), as in MERL's reference reader.
MERL_SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
_HEADER_BYTES = 3 * 4
_N = int(np.prod(GRID_SHAPE))


@dataclass
class MERLData:
    """The stored (unscaled) float64 numbers of a MERL file, shape ``(3, 90, 90, 180)``."""

    raw: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """True where all three channels hold a measurement (no negative marker)."""
        return np.all(self.raw >= 0, axis=0)

    def to_table(self, source: str = "") -> BRDFTable:
        """Scaled linear-RGB :class:`BRDFTable` with invalid entries masked to zero."""
        rgb = np.moveaxis(self.raw, 0, -1) * MERL_SCALE
        valid = self.valid
        rgb[~valid] = 0.0
        meta = {"source": source, "format": "MERL binary", "invalid_entries": int((~valid).sum()),
                "description": Path(source).stem if source else ""}
        return BRDFTable(rgb.astype(np.float32), None, ("R", "G", "B"), meta)

    @classmethod
    def from_table(cls, table: BRDFTable) -> "MERLData":
        """Inverse scaling of an RGB table (a spectral table is projected to RGB first)."""
        rgb = table.to_rgb().values.astype(np.float64) / MERL_SCALE
        return cls(np.ascontiguousarray(np.moveaxis(rgb, -1, 0)))


def read_merl(path: str | Path) -> MERLData:
    """Read a MERL ``.binary`` file; raises :class:`BRDFFormatError` naming the file and problem."""
    path = Path(path)
    if not path.is_file():
        raise BRDFFormatError(path, "no such file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise BRDFFormatError(path, f"cannot read file ({exc.strerror or exc})") from None
    if len(data) < _HEADER_BYTES:
        raise BRDFFormatError(path, f"truncated MERL file: {len(data)} bytes, header needs 12")
    dims = tuple(int(d) for d in np.frombuffer(data[:_HEADER_BYTES], dtype="<i4"))
    if dims != GRID_SHAPE:
        raise BRDFFormatError(path, f"not a MERL isotropic BRDF: dims {dims}, expected {GRID_SHAPE}")
    expected = _HEADER_BYTES + 3 * _N * 8
    if len(data) != expected:
        kind = "truncated" if len(data) < expected else "oversized"
        raise BRDFFormatError(path, f"{kind} MERL file: {len(data)} bytes, expected {expected}")
    raw = np.frombuffer(data[_HEADER_BYTES:], dtype="<f8").reshape((3,) + GRID_SHAPE).copy()
    # negative entries are MERL's "no measurement" marker; NaN, Inf and values that overflow
    # float32 tables once scaled are corruption
    reason = bad_values(raw * MERL_SCALE[:, None, None, None], allow_negative=True)
    if reason:
        raise BRDFFormatError(path, f"corrupt MERL file: {reason}")
    data = MERLData(raw)
    if not data.valid.any():
        raise BRDFFormatError(path, "MERL file holds no valid measurement (every entry is negative)")
    return data


def write_merl(path: str | Path, data: MERLData | BRDFTable, overwrite: bool = False) -> Path:
    """Write a MERL ``.binary`` file atomically (raw numbers are written bit for bit)."""
    if isinstance(data, BRDFTable):
        data = MERLData.from_table(data)
    raw = np.asarray(data.raw, dtype="<f8")
    if raw.shape != (3,) + GRID_SHAPE:
        raise BRDFFormatError(path, f"MERL data must have shape (3, 90, 90, 180), got {raw.shape}")
    with atomic_write(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(np.asarray(GRID_SHAPE, dtype="<i4").tobytes())
            fh.write(np.ascontiguousarray(raw).tobytes())
    return Path(path)
