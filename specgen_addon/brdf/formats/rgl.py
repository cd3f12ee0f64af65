"""RGL ``.bsdf`` files: the adaptive parameterisation of Dupuy & Jakob (2018).

Reference: J. Dupuy and W. Jakob, "An Adaptive Parameterization for Efficient Material Acquisition
and Rendering", ACM TOG 37(6), 2018. Reference readers: rgl-epfl/brdf-loader (``powitacq.inl``,
``powitacq_rgb.inl``) and Mitsuba 3's ``measured`` plugin; this is an independent, vectorised numpy
re-implementation of their evaluation path.

A file is a little-endian *tensor file* (see :func:`read_tensor_file`). An isotropic measurement
stores, per incident elevation ``θi`` (the slices of ``theta_i``):

* ``ndf`` (2, n) and ``sigma`` (2, n): the microfacet distribution ``D(ωm)`` and the projected
  area ``σ(ωi)`` on the unit square ``u = (√(θ·2/π), (φ+π)/2π)``;
* ``vndf`` (1, S, n, n): the visible-normal density whose warp ``[0,1]² → ωm`` (a
  :class:`ConditionalWarp2D`) adapts the measurement grid to the material;
* ``rgb`` (1, S, 3, m, m) or ``spectra`` (1, S, Λ, m, m) with ``wavelengths`` (Λ,) in nm: the
  reflectance factor sampled on that warped grid.

Evaluation (as in the reference readers): ``ωm = normalize(ωi + ωo)``; invert the VNDF warp at ``u(ωm)``
(with ``φm`` relative to ``φi``) to find the sample point; look the reflectance up there
(bilinear, linear across ``θi`` slices); multiply by ``D(ωm) / (4 σ(ωi))``. The reference readers
document this product as ``fr · cos θo`` (``powitacq.h``: "evaluate f_r * cos"; Mitsuba's
``BSDF::eval`` includes the cosine), so :meth:`RGLBSDF.eval` divides by ``cos θo`` and returns
``fr`` in sr⁻¹. The tests check the consequence on real data: the felt is near-Lambertian in ``fr``
and its directional albedo is below one.
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from specgen_addon.common.errors import BRDFFormatError, SpecGenError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.common.limits import bad_values
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable, CancelFn, ProgressFn
from specgen_addon.spectral import spectra

# --------------------------------------------------------------------------------------------
# Tensor file I/O
# --------------------------------------------------------------------------------------------

TENSOR_MAGIC = b"tensor_file\0"
TENSOR_VERSION = (1, 0)
#: dtype codes of the tensor file format (0 is "invalid").
TENSOR_DTYPES: dict[int, np.dtype] = {
    1: np.dtype("<u1"), 2: np.dtype("<i1"), 3: np.dtype("<u2"), 4: np.dtype("<i2"),
    5: np.dtype("<u4"), 6: np.dtype("<i4"), 7: np.dtype("<u8"), 8: np.dtype("<i8"),
    9: np.dtype("<f2"), 10: np.dtype("<f4"), 11: np.dtype("<f8"),
}
_DTYPE_CODES = {dt: code for code, dt in TENSOR_DTYPES.items()}
_HEADER = struct.Struct("<12sBBI")        # magic, major, minor, field count
_FIELD_HEAD = struct.Struct("<HBQ")       # ndim, dtype code, absolute offset


class _Reader:
    """Bounds-checked cursor over the file bytes; every overrun becomes a BRDFFormatError."""

    def __init__(self, path: Path, data: bytes):
        self.path, self.data, self.pos = path, data, 0

    def take(self, fmt: struct.Struct | str, what: str) -> tuple:
        fmt = struct.Struct(fmt) if isinstance(fmt, str) else fmt
        end = self.pos + fmt.size
        if end > len(self.data):
            raise BRDFFormatError(self.path, f"truncated tensor file: header ends inside {what} "
                                             f"(byte {self.pos} of {len(self.data)})")
        values = fmt.unpack_from(self.data, self.pos)
        self.pos = end
        return values


def read_tensor_file(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a tensor file (the container of RGL ``.bsdf`` files) into named arrays.

    Layout (little-endian): ``"tensor_file\\0"``, u8 major, u8 minor, u32 field count; per field
    u16 name length, name, u16 ndim, u8 dtype code, u64 absolute offset, ndim × u64 shape; the
    data of each field is C-ordered at its offset.

    Raises
    ------
    BRDFFormatError
        Wrong magic, unknown major version, unknown dtype, or a header/field running past the end
        of the file.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise BRDFFormatError(path, f"cannot read file ({exc.strerror or exc})") from exc
    reader = _Reader(path, data)
    if len(data) < _HEADER.size:
        raise BRDFFormatError(path, f"not a tensor file: {len(data)} bytes is shorter than the "
                                    f"{_HEADER.size}-byte header")
    magic, major, minor, n_fields = reader.take(_HEADER, "the file header")
    if magic != TENSOR_MAGIC:
        raise BRDFFormatError(path, f"not a tensor file: magic {magic[:11]!r} is not 'tensor_file'")
    if major != TENSOR_VERSION[0]:
        raise BRDFFormatError(path, f"unknown tensor file version {major}.{minor} "
                                    f"(supported: {TENSOR_VERSION[0]}.x)")
    descriptors = []
    for index in range(n_fields):
        (name_len,) = reader.take("<H", f"the name length of field {index}")
        (raw_name,) = reader.take(f"<{name_len}s", f"the name of field {index}")
        name = raw_name.decode("utf-8", errors="replace")
        ndim, code, offset = reader.take(_FIELD_HEAD, f"the descriptor of field {name!r}")
        shape = reader.take(f"<{ndim}Q", f"the shape of field {name!r}") if ndim else ()
        if code not in TENSOR_DTYPES:
            raise BRDFFormatError(path, f"field {name!r} has unknown dtype code {code}")
        descriptors.append((name, TENSOR_DTYPES[code], offset, tuple(shape)))
    fields: dict[str, np.ndarray] = {}
    for name, dtype, offset, shape in descriptors:
        count = math.prod(shape)
        end = offset + count * dtype.itemsize
        if end > len(data):
            raise BRDFFormatError(path, f"truncated tensor file: field {name!r} {shape} "
                                        f"needs bytes {offset}–{end}, file has {len(data)}")
        fields[name] = np.frombuffer(data, dtype=dtype, count=count, offset=offset).reshape(shape)
    return fields


def write_tensor_file(path: str | os.PathLike, fields: Mapping[str, np.ndarray],
                      overwrite: bool = False) -> None:
    """Write named arrays as a tensor file (inverse of :func:`read_tensor_file`), atomically.

    Field data follow the header in the given order, each aligned to 8 bytes like the RGL files.
    """
    arrays = {name: np.ascontiguousarray(a) for name, a in fields.items()}
    for name, a in arrays.items():
        if a.dtype.newbyteorder("<") not in _DTYPE_CODES:
            raise TypeError(f"field {name!r}: dtype {a.dtype} has no tensor file code")
    header = bytearray(_HEADER.pack(TENSOR_MAGIC, *TENSOR_VERSION, len(arrays)))
    header_size = len(header) + sum(2 + len(n.encode()) + _FIELD_HEAD.size + 8 * a.ndim
                                    for n, a in arrays.items())
    offset = _align8(header_size)
    blobs = []
    for name, a in arrays.items():
        le = a.astype(a.dtype.newbyteorder("<"), copy=False)
        raw = name.encode()
        header += struct.pack("<H", len(raw)) + raw
        header += _FIELD_HEAD.pack(a.ndim, _DTYPE_CODES[le.dtype], offset)
        header += struct.pack(f"<{a.ndim}Q", *a.shape)
        blobs.append((offset, le.tobytes()))
        offset = _align8(offset + le.nbytes)
    out = bytearray(offset)
    out[:len(header)] = header
    for start, blob in blobs:
        out[start:start + len(blob)] = blob
    with atomic_write(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(bytes(out))


def _align8(n: int) -> int:
    return (n + 7) // 8 * 8


# --------------------------------------------------------------------------------------------
# Unit-square parameterisation and interpolants
# --------------------------------------------------------------------------------------------

def theta_to_u(theta: np.ndarray) -> np.ndarray:
    """Elevation (radians) → unit coordinate ``√(θ·2/π)``."""
    return np.sqrt(np.maximum(theta, 0.0) * (2.0 / np.pi))


def phi_to_u(phi: np.ndarray) -> np.ndarray:
    """Azimuth (radians, in [-π, π]) → unit coordinate ``(φ+π)/2π``."""
    return (phi + np.pi) * (0.5 / np.pi)


def _elevation(v: np.ndarray) -> np.ndarray:
    """Polar angle of unit vectors, stable near the pole: ``2 asin(|v - n| / 2)``."""
    dist = np.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2 + (v[..., 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.clip(0.5 * dist, 0.0, 1.0))


def _patch(u: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell index (clamped to ``[0, n-2]``) and in-cell weight of unit coordinates on ``n`` nodes."""
    pos = np.clip(u, 0.0, 1.0) * (n - 1)
    idx = np.minimum(pos.astype(np.int64), n - 2)
    return idx, pos - idx


def _bilinear(grid: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``grid`` (ny, nx) at unit points ``u`` (..., 2) = (x, y)."""
    ny, nx = grid.shape
    ix, fx = _patch(u[..., 0], nx)
    iy, fy = _patch(u[..., 1], ny)
    g = grid.astype(np.float64, copy=False)
    top = g[iy, ix] * (1 - fx) + g[iy, ix + 1] * fx
    bottom = g[iy + 1, ix] * (1 - fx) + g[iy + 1, ix + 1] * fx
    return top * (1 - fy) + bottom * fy


@dataclass(frozen=True)
class SliceWeights:
    """Linear interpolation between parameter slices: ``(1-w)·A[i0] + w·A[i0+1]``."""

    index: np.ndarray   # (N,) int64, lower slice
    weight: np.ndarray  # (N,) float64 in [0, 1]
    stride: int         # 0 when there is a single slice

    @classmethod
    def locate(cls, nodes: np.ndarray, value: np.ndarray) -> "SliceWeights":
        """Slice interval of ``value`` among sorted ``nodes`` (clamped at both ends)."""
        n = nodes.size
        if n == 1:
            return cls(np.zeros(value.shape, np.int64), np.zeros(value.shape), 0)
        i0 = np.clip(np.searchsorted(nodes, value, side="right") - 1, 0, n - 2)
        p0, p1 = nodes[i0], nodes[i0 + 1]
        return cls(i0, np.clip((value - p0) / (p1 - p0), 0.0, 1.0), 1)

    def lerp(self, flat: np.ndarray, slice_size: int, offset: np.ndarray) -> np.ndarray:
        """Interpolated ``flat[slice·slice_size + offset]`` (flat: the slices, concatenated)."""
        i = self.index * slice_size + offset
        a = flat[i]
        if not self.stride:
            return a
        return a + self.weight * (flat[i + slice_size] - a)


class ConditionalWarp2D:
    """Piecewise-bilinear 2D density with one interpolated parameter, and its inverse warp.

    The density on the unit square is the bilinear interpolant of ``data`` (P, ny, nx), one
    (ny, nx) grid per parameter node; sampling is marginal (rows, ``y``) then conditional
    (columns, ``x``), each inverting a piecewise-linear density in closed form. Between parameter
    nodes the normalised densities and their CDFs are interpolated linearly, as in the reference
    ``Marginal2D<Dimension>`` (powitacq.inl) that measured BRDFs use.
    """

    def __init__(self, data: np.ndarray, param_nodes: np.ndarray):
        data = np.asarray(data, dtype=np.float64)
        p, ny, nx = data.shape
        # Conditional CDF along x of each row (trapezoid rule, patch width 1).
        cond = np.zeros_like(data)
        cond[..., 1:] = np.cumsum(0.5 * (data[..., 1:] + data[..., :-1]), axis=-1)
        row_mass = cond[..., -1]
        marg = np.zeros((p, ny))
        marg[:, 1:] = np.cumsum(0.5 * (row_mass[:, 1:] + row_mass[:, :-1]), axis=-1)
        total = marg[:, -1:]
        if np.any(total <= 0) or not np.all(np.isfinite(total)):
            raise ValueError("density slice with zero or non-finite mass")
        norm = 1.0 / total
        self.shape = (ny, nx)
        self.param_nodes = np.asarray(param_nodes, dtype=np.float64)
        self._data = (data * norm[..., None]).ravel()
        self._cond = (cond * norm[..., None]).ravel()
        self._marg = (marg * norm).ravel()

    def invert(self, u: np.ndarray, param: np.ndarray) -> np.ndarray:
        """Inverse warp: points ``u`` (N, 2) of the warped domain → uniform samples (N, 2)."""
        ny, nx = self.shape
        size = ny * nx
        w = SliceWeights.locate(self.param_nodes, param)
        ix, fx = _patch(u[:, 0], nx)
        iy, fy = _patch(u[:, 1], ny)
        base = iy * nx + ix
        d = self._data
        v00, v10 = w.lerp(d, size, base), w.lerp(d, size, base + 1)
        v01, v11 = w.lerp(d, size, base + nx), w.lerp(d, size, base + nx + 1)
        c0 = v00 + fy * (v01 - v00)           # density along x on this row, at x = ix
        c1 = v10 + fy * (v11 - v10)           # ... at x = ix + 1
        # Invert x: CDF of the row (bilinear in y) up to ix, plus the partial cell, normalised.
        x = fx * (c0 + 0.5 * fx * (c1 - c0))
        cd0, cd1 = w.lerp(self._cond, size, base), w.lerp(self._cond, size, base + nx)
        x += cd0 + fy * (cd1 - cd0)
        row = iy * nx + (nx - 1)
        r0, r1 = w.lerp(self._cond, size, row), w.lerp(self._cond, size, row + nx)
        x /= r0 + fy * (r1 - r0)
        # Invert y: marginal CDF up to iy plus the partial cell.
        y = fy * (r0 + 0.5 * fy * (r1 - r0)) + w.lerp(self._marg, ny, iy)
        return np.stack([x, y], axis=-1)


# --------------------------------------------------------------------------------------------
# The measured BRDF
# --------------------------------------------------------------------------------------------

_REQUIRED = ("description", "phi_i", "theta_i", "ndf", "sigma", "vndf", "luminance", "jacobian")
#: Number of samples per chunk when evaluating many directions (bounds temporary memory).
EVAL_CHUNK = 1 << 17


@dataclass
class RGLBSDF:
    """An isotropic RGL measurement, evaluated as ``fr`` (sr⁻¹) at direction pairs.

    Use :meth:`load`. ``channels`` are the file's native channels: ``("R", "G", "B")`` for RGB
    files, or one per wavelength of ``wavelengths`` (nm) for spectral files.
    """

    path: Path
    description: str
    theta_i: np.ndarray            # (S,) incident elevations of the slices, radians
    ndf: np.ndarray                # (ny, nx) D on the unit square
    sigma: np.ndarray              # (ny, nx) projected area on the unit square
    vndf: ConditionalWarp2D
    reflectance: np.ndarray        # (S, m, m, C) float32: rgb or spectra on the warped grid
    wavelengths: np.ndarray | None  # (C,) nm for spectral files, None for RGB
    jacobian: bool                 # apply D/(4σ) (the reference skips it when the flag is 0)
    version: str = "1.0"
    metadata: dict = field(default_factory=dict)

    # ---- construction ---------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike) -> "RGLBSDF":
        """Read and validate an isotropic RGL ``.bsdf`` file (RGB or spectral)."""
        path = Path(path)
        f = read_tensor_file(path)
        return cls.from_fields(path, f)

    @classmethod
    def from_fields(cls, path: Path, f: Mapping[str, np.ndarray]) -> "RGLBSDF":
        """Validate the fields of a tensor file as an isotropic RGL measurement."""
        def fail(reason: str) -> BRDFFormatError:
            return BRDFFormatError(path, reason)

        missing = [n for n in _REQUIRED if n not in f]
        if "rgb" not in f and "spectra" not in f:
            missing.append("rgb or spectra")
        if missing:
            raise fail(f"not an RGL BSDF: missing field(s) {', '.join(missing)}")
        spectral = "spectra" in f
        if spectral and "wavelengths" not in f:
            raise fail("spectral RGL file has no 'wavelengths' field")

        def check(name: str, ndim: int, kind: str = "f") -> np.ndarray:
            a = f[name]
            if a.ndim != ndim or a.dtype.kind != kind:
                raise fail(f"field {name!r} should be a {ndim}-d {'float' if kind == 'f' else 'uint'} "
                           f"array, got shape {a.shape} dtype {a.dtype}")
            reason = bad_values(a, allow_negative=True) if kind == "f" else None
            if reason:
                raise fail(f"field {name!r} has non-finite values: {reason}")
            return a

        phi_i, theta_i = check("phi_i", 1), check("theta_i", 1).astype(np.float64)
        ndf, sigma, vndf = check("ndf", 2), check("sigma", 2), check("vndf", 4)
        description, jac = check("description", 1, "u"), check("jacobian", 1, "u")
        check("luminance", 4)
        refl = check("spectra" if spectral else "rgb", 5)
        n_phi, n_theta = phi_i.size, theta_i.size
        if n_phi != 1:
            raise fail(f"anisotropic measurement ({n_phi} φi slices) is not supported; "
                       "only isotropic files (one φi slice)")
        if n_theta < 1 or np.any(np.diff(theta_i) <= 0):
            raise fail(f"theta_i must be strictly increasing, got {theta_i.tolist()}")
        if vndf.shape[:2] != (n_phi, n_theta) or min(vndf.shape[2:]) < 2:
            raise fail(f"vndf has shape {vndf.shape}, expected ({n_phi}, {n_theta}, ny, nx)")
        if min(ndf.shape) < 2 or min(sigma.shape) < 2:
            raise fail(f"ndf {ndf.shape} / sigma {sigma.shape} need at least 2×2 nodes")
        if jac.shape != (1,):
            raise fail(f"jacobian should have shape (1,), got {jac.shape}")
        n_channels = 3
        wavelengths = None
        if spectral:
            wavelengths = check("wavelengths", 1).astype(np.float64)
            n_channels = wavelengths.size
            if n_channels < 2 or np.any(np.diff(wavelengths) <= 0):
                raise fail("wavelengths must hold at least 2 strictly increasing values (nm)")
        if (refl.shape[:3] != (n_phi, n_theta, n_channels) or refl.shape[3] != refl.shape[4]
                or refl.shape[3] < 2):
            raise fail(f"{'spectra' if spectral else 'rgb'} has shape {refl.shape}, expected "
                       f"({n_phi}, {n_theta}, {n_channels}, m, m)")
        try:
            warp = ConditionalWarp2D(vndf[0], theta_i)
        except ValueError as exc:
            raise fail(f"vndf is not a valid density ({exc})") from None
        if np.any(sigma <= 0):
            raise fail("sigma (projected area) must be positive")
        version = f.get("version")
        try:
            parts = [] if version is None else np.asarray(version).ravel().tolist()
            if any(isinstance(v, bool) or not float(v).is_integer() for v in parts):
                raise ValueError("not whole")
            version_str = ".".join(str(int(v)) for v in parts) if version is not None else "unknown"
        except (ValueError, TypeError, OverflowError):
            raise fail(f"field 'version' should hold whole numbers, got {np.asarray(version).tolist()}") from None
        text = bytes(description).decode("utf-8", errors="replace").rstrip("\0")
        bsdf = cls(
            path=path, description=text, theta_i=theta_i,
            ndf=ndf.astype(np.float64), sigma=sigma.astype(np.float64), vndf=warp,
            reflectance=np.ascontiguousarray(np.moveaxis(refl[0], 1, -1), dtype=np.float32),
            wavelengths=wavelengths, jacobian=bool(jac[0]), version=version_str)
        bsdf.metadata = {
            "format": "RGL tensor file (Dupuy & Jakob 2018)", "source": str(path),
            "description": text, "version": version_str, "units": "sr^-1",
            "kind": "spectral" if spectral else "rgb", "isotropic": True,
            "theta_i_slices": n_theta, "grid": int(refl.shape[3]),
            "vndf_resolution": tuple(int(s) for s in vndf.shape[2:]),
            "channels": list(bsdf.channels),
        }
        return bsdf

    # ---- properties -----------------------------------------------------------------------
    @property
    def is_spectral(self) -> bool:
        return self.wavelengths is not None

    @property
    def channels(self) -> tuple[str, ...]:
        if self.wavelengths is None:
            return ("R", "G", "B")
        return tuple(f"{w:g}nm" for w in self.wavelengths)

    def info(self) -> dict:
        """Metadata for ``specgen info``: kind, description, slices, wavelength range."""
        info = {k: v for k, v in self.metadata.items() if k != "format"}
        info["channels"] = len(self.channels)
        if self.is_spectral:
            info["wavelengths_nm"] = [float(self.wavelengths[0]), float(self.wavelengths[-1])]
        return info

    # ---- evaluation -----------------------------------------------------------------------
    def eval_native(self, wi: np.ndarray, wo: np.ndarray,
                    reflectance: np.ndarray | None = None) -> np.ndarray:
        """``fr`` (sr⁻¹) in the file's own channels (or in ``reflectance``'s), shape (N, C).

        ``wi``, ``wo``: unit vectors (N, 3) in the local frame (normal +z). Zero unless both are
        strictly above the horizon. ``reflectance`` (S, m, m, C) replaces the file's table, e.g.
        after resampling its wavelength axis (everything is linear in that axis).
        """
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        wi, wo = np.broadcast_arrays(wi, wo)
        table = self.reflectance if reflectance is None else reflectance
        n = wi.shape[0]
        out = np.zeros((n, table.shape[-1]), dtype=np.float32)
        for start in range(0, n, EVAL_CHUNK):
            sl = slice(start, start + EVAL_CHUNK)
            out[sl] = self._eval_chunk(wi[sl], wo[sl], table)
        return out

    def _eval_chunk(self, wi: np.ndarray, wo: np.ndarray, table: np.ndarray) -> np.ndarray:
        out = np.zeros((wi.shape[0], table.shape[-1]), dtype=np.float32)
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if not np.any(above):
            return out
        wi, wo = wi[above], wo[above]
        wm = wi + wo
        wm /= np.linalg.norm(wm, axis=-1, keepdims=True)
        theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
        theta_m, phi_m = _elevation(wm), np.arctan2(wm[:, 1], wm[:, 0])
        u_wi = np.stack([theta_to_u(theta_i), phi_to_u(phi_i)], axis=-1)
        u_m = phi_to_u(phi_m - phi_i)            # isotropic: φm relative to φi
        u_wm = np.stack([theta_to_u(theta_m), u_m - np.floor(u_m)], axis=-1)
        sample = self.vndf.invert(u_wm, theta_i)
        value = self._lookup(table, sample, theta_i)
        np.maximum(value, 0.0, out=value)        # out-of-gamut RGB / noisy spectra go negative
        if self.jacobian:
            value *= (_bilinear(self.ndf, u_wm) / (4.0 * _bilinear(self.sigma, u_wi)))[:, None]
        value /= wo[:, 2:3]                      # the tables hold fr·cos θo
        out[above] = value
        return out

    def _lookup(self, table: np.ndarray, sample: np.ndarray, theta_i: np.ndarray) -> np.ndarray:
        """Bilinear lookup of ``table`` (S, m, m, C) at ``sample`` (N, 2), linear across θi."""
        s, m, _, c = table.shape
        flat = table.reshape(s * m * m, c)
        w = SliceWeights.locate(self.theta_i, theta_i)
        ix, fx = _patch(sample[:, 0], m)
        iy, fy = _patch(sample[:, 1], m)
        base = w.index * (m * m) + iy * m + ix
        fx, fy = fx[:, None], fy[:, None]
        acc = None
        for slice_w, off in ((1.0 - w.weight, 0), (w.weight, w.stride * m * m)):
            b = base + off
            v = ((flat[b] * (1 - fx) + flat[b + 1] * fx) * (1 - fy)
                 + (flat[b + m] * (1 - fx) + flat[b + m + 1] * fx) * fy)
            acc = v * slice_w[:, None] if acc is None else acc + v * slice_w[:, None]
            if not w.stride:
                break
        return acc

    def eval(self, wi: np.ndarray, wo: np.ndarray,
             wavelengths_nm: np.ndarray | None = None) -> np.ndarray:
        """``fr`` (sr⁻¹) at ``(wi, wo)``: (N, Λ) at ``wavelengths_nm``.

        Spectral files are linearly interpolated from their own wavelengths (360–1000 nm) onto the
        requested ones; with ``wavelengths_nm=None`` the file's own channels are returned (for
        RGB files: linear sRGB, same as :meth:`eval_rgb`).
        """
        if wavelengths_nm is None:
            return self.eval_native(wi, wo)
        if not self.is_spectral:
            raise SpecGenError(f"{self.path.name} is an RGB measurement: it has no spectra to "
                             "evaluate at wavelengths (use eval_rgb)")
        return self.eval_native(wi, wo, self.resampled_reflectance(wavelengths_nm))

    def resampled_reflectance(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """The reflectance table linearly interpolated onto ``wavelengths_nm`` (nm)."""
        target = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        lo, hi = self.wavelengths[0], self.wavelengths[-1]
        if target.min() < lo - 1e-6 or target.max() > hi + 1e-6:
            raise SpecGenError(f"wavelengths {target.min():g}–{target.max():g} nm outside the "
                             f"measured {lo:g}–{hi:g} nm of {self.path.name}")
        return (self.reflectance @ _interp_matrix(self.wavelengths, target).T).astype(np.float32)

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Linear sRGB ``fr`` (sr⁻¹), (N, 3); spectral files are integrated under D65."""
        if not self.is_spectral:
            return self.eval_native(wi, wo)

        visible = (self.wavelengths >= 360.0) & (self.wavelengths <= 830.0)
        wl = self.wavelengths[visible]
        # Integrating is linear, so fold the spectral→sRGB map into the table once.
        to_rgb = spectra.reflectance_to_linear_srgb(np.eye(wl.size), wl)      # (Λ, 3)
        table = self.reflectance[..., visible] @ to_rgb.astype(np.float32)
        return self.eval_native(wi, wo, table)


def _interp_matrix(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Matrix (len(dst), len(src)) of linear interpolation weights from ``src`` to ``dst``."""
    j = np.clip(np.searchsorted(src, dst, side="right") - 1, 0, src.size - 2)
    t = np.clip((dst - src[j]) / (src[j + 1] - src[j]), 0.0, 1.0)
    mat = np.zeros((dst.size, src.size))
    rows = np.arange(dst.size)
    mat[rows, j] = 1.0 - t
    mat[rows, j + 1] += t
    return mat


def write_rgl(path: str | os.PathLike, *, description: str, theta_i: np.ndarray,
              ndf: np.ndarray, sigma: np.ndarray, vndf: np.ndarray, luminance: np.ndarray,
              rgb: np.ndarray | None = None, spectra: np.ndarray | None = None,
              wavelengths: np.ndarray | None = None, jacobian: bool = True,
              valid: np.ndarray | None = None, overwrite: bool = False) -> Path:
    """Write an isotropic RGL ``.bsdf`` file in the published field order and dtypes.

    Give either ``rgb`` (1, S, 3, m, m) or ``spectra`` (1, S, Λ, m, m) with ``wavelengths`` (Λ,)
    in nm. Shapes follow :class:`RGLBSDF`; the file is re-read and validated before it replaces
    ``path``, so an invalid measurement is never written.
    """
    if (rgb is None) == (spectra is None):
        raise SpecGenError("write_rgl needs exactly one of rgb or spectra")
    if spectra is not None and wavelengths is None:
        raise SpecGenError("a spectral RGL file needs wavelengths (nm)")
    f32 = lambda a: np.asarray(a, dtype="<f4")  # noqa: E731 - the format stores float32
    fields: dict[str, np.ndarray] = {
        "version": np.array([1, 0], dtype="<u4"),
        "description": np.frombuffer(description.encode("utf-8"), dtype=np.uint8),
        "phi_i": np.zeros(1, dtype="<f4"), "theta_i": f32(theta_i),
        "sigma": f32(sigma), "ndf": f32(ndf), "vndf": f32(vndf), "luminance": f32(luminance),
    }
    if rgb is not None:
        fields["rgb"] = f32(rgb)
    else:
        fields["wavelengths"] = f32(wavelengths)
        fields["spectra"] = f32(spectra)
    fields["jacobian"] = np.array([int(jacobian)], dtype=np.uint8)
    m = fields["rgb" if rgb is not None else "spectra"].shape[-1]
    fields["valid"] = (np.full(m * m, 255, np.uint8) if valid is None
                       else np.asarray(valid, dtype=np.uint8))
    path = Path(path)
    with atomic_write(path, overwrite=overwrite) as tmp:
        write_tensor_file(tmp, fields, overwrite=True)
        RGLBSDF.load(tmp)
    return path


def read_rgl(path: str | os.PathLike) -> RGLBSDF:
    """Read an isotropic RGL ``.bsdf`` file (RGB or spectral). See :class:`RGLBSDF`."""
    return RGLBSDF.load(path)


#: Which of a grid point's two direction orders :func:`tabulate_rgl` evaluates (see there).
TABULATION_ORDERS = ("nearer", "fixed")


def tabulate_rgl(bsdf: RGLBSDF, wavelengths_nm: np.ndarray | None = None,
                 progress: ProgressFn | None = None, cancel: CancelFn | None = None,
                 order: str = "nearer") -> BRDFTable:
    """Resample a measurement onto the MERL grid (90 θh × 90 θd × 180 φd) as a :class:`BRDFTable`.

    Spectral files are interpolated onto ``wavelengths_nm`` (nm; default: the file's own);
    RGB files give an RGB table (``wavelengths_nm`` must be None). Values are ``fr`` in sr⁻¹ at
    ``φh = 0`` (the file is isotropic). Each grid point is evaluated with the direction nearer the
    normal as ``wo``: :meth:`RGLBSDF.eval` divides the measured ``fr·cos θo`` by ``cos θo``, and
    the measurement does not vanish at grazing ``θo``; by reciprocity either order is the same
    point, and this one keeps grazing-``θo`` artefacts out of the table. ``order="fixed"``
    evaluates the order :func:`io_from_half_diff` gives instead: the real-file training targets
    and the model card's table ceilings. A measurement is not quite reciprocal (8 θi slices,
    linear across them), so the two orders score differently, by up to ±10 dB in one scene
    (docs/model-card.md, "Real materials").
    """
    if order not in TABULATION_ORDERS:
        raise SpecGenError(f"unknown tabulation order {order!r}; choose one of {', '.join(TABULATION_ORDERS)}")
    if bsdf.is_spectral:
        wavelengths = bsdf.wavelengths if wavelengths_nm is None else np.asarray(wavelengths_nm, float)
        table = bsdf.resampled_reflectance(wavelengths)
        channels: tuple[str, ...] = ()
    else:
        if wavelengths_nm is not None:
            raise SpecGenError(f"{bsdf.path.name} is an RGB measurement: tabulate it without wavelengths")
        wavelengths, table, channels = None, None, bsdf.channels

    def fr_half_diff(theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
        wi, wo = io_from_half_diff(theta_h, theta_d, phi_d)
        if order == "fixed":
            return bsdf.eval_native(wi, wo, table)
        # (wi, wo) and (wo, wi) are the same grid point (reciprocity); evaluate the order whose
        # second direction is nearer the normal, so the division by cos θo stays well conditioned
        # (the measured fr·cos θo does not vanish at grazing θo, fr/cos would diverge there).
        swap = (wi[:, 2] > wo[:, 2])[:, None]
        return bsdf.eval_native(np.where(swap, wo, wi), np.where(swap, wi, wo), table)

    metadata = {"source": str(bsdf.path), "description": bsdf.description,
                "format": bsdf.metadata.get("format"), "tabulated_from": "rgl"}
    return BRDFTable.tabulate(fr_half_diff, wavelengths, channels, metadata,
                              progress=progress, cancel=cancel)
