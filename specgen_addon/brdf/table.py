"""Tabulated BRDFs on the MERL grid, spectral or RGB, with μ-law helpers.

Grid (Matusik et al. 2003): 90 √-warped ``theta_h`` samples, 90 ``theta_d``, 180 ``phi_d`` over
``[0, π)`` (isotropic, reciprocal). Sample ``i`` of ``theta_h`` sits at ``(i/90)² · π/2``; ``theta_d``
at ``j/90 · π/2``; ``phi_d`` at ``k/180 · π``. Values are BRDF ``f_r`` in sr⁻¹ (not multiplied by
any cosine), one column per wavelength (nm) or per RGB channel.
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import BRDFFormatError, Cancelled, SpecGenError
from specgen_addon.common.atomic_io import atomic_write, write_npz
from specgen_addon.brdf.rusinkiewicz import fold_phi_d, half_diff_from_io
from specgen_addon.common.limits import bad_values
from specgen_addon.brdf.material_file import COMPACT_FORMAT, load_compact, save_compact
from specgen_addon.spectral.spectra import reflectance_to_linear_srgb

N_THETA_H = 90
N_THETA_D = 90
N_PHI_D = 180
GRID_SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D)
TABLE_FORMAT = "specgen-brdf-table"
TABLE_FORMAT_VERSION = 1
MU_LAW_MU = 255.0

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]


def mu_law_encode(r: np.ndarray, mu: float = MU_LAW_MU) -> np.ndarray:
    """Paper's μ-law compression ``r' = log(1 + μ|r|) / log(1 + μ)`` (μ = 255)."""
    return np.log1p(mu * np.abs(r)) / np.log1p(mu)


def mu_law_decode(rp: np.ndarray, mu: float = MU_LAW_MU) -> np.ndarray:
    """Inverse μ-law for non-negative BRDF values: ``r = ((1 + μ)^r' − 1) / μ``."""
    return np.expm1(np.asarray(rp) * np.log1p(mu)) / mu


def mu_law_decode_inplace(rp: np.ndarray, mu: float = MU_LAW_MU) -> None:
    """:func:`mu_law_decode` of a float32 network output in place, clipped at 0 first (no
    temporaries: a full table is 122 MB at 21 bands)."""
    np.clip(rp, 0.0, None, out=rp)
    rp *= np.float32(math.log1p(mu))
    np.expm1(rp, out=rp)
    rp /= np.float32(mu)


def theta_h_index(theta_h: np.ndarray) -> np.ndarray:
    """Continuous MERL index of ``theta_h`` (radians): ``sqrt(theta_h / (π/2)) · 90``."""
    return np.sqrt(np.clip(theta_h, 0.0, np.pi / 2) / (np.pi / 2)) * N_THETA_H


def theta_d_index(theta_d: np.ndarray) -> np.ndarray:
    """Continuous MERL index of ``theta_d`` (radians): ``theta_d / (π/2) · 90``."""
    return np.clip(theta_d, 0.0, np.pi / 2) / (np.pi / 2) * N_THETA_D


def phi_d_index(phi_d: np.ndarray) -> np.ndarray:
    """Continuous MERL index of ``phi_d`` (radians, folded into [0, π)): ``phi_d / π · 180``."""
    return fold_phi_d(phi_d) / np.pi * N_PHI_D


def grid_angles() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample positions (radians) of the MERL grid: ``theta_h[90], theta_d[90], phi_d[180]``."""
    th = (np.arange(N_THETA_H) / N_THETA_H) ** 2 * (np.pi / 2)
    td = np.arange(N_THETA_D) / N_THETA_D * (np.pi / 2)
    pd = np.arange(N_PHI_D) / N_PHI_D * np.pi
    return th, td, pd


def _linear_weights(x: np.ndarray, n: int, periodic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if periodic:
        x = np.mod(x, n)
        i0 = np.floor(x).astype(np.int64)
        t = x - i0
        return i0 % n, (i0 + 1) % n, t
    x = np.clip(x, 0.0, n - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    return i0, i0 + 1, x - i0


@dataclass
class BRDFTable:
    """A tabulated isotropic BRDF: ``values[θh, θd, φd, c]`` in sr⁻¹ on the MERL grid.

    ``wavelengths`` (nm, increasing) names the columns of a spectral table; for an RGB table it is
    ``None`` and ``channels`` is ``("R", "G", "B")`` (linear sRGB). ``metadata`` holds free-form
    provenance: ``source``, ``description``, ``units`` (always ``"1/sr"``).
    """

    values: np.ndarray
    wavelengths: np.ndarray | None = None
    channels: tuple[str, ...] = ()
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=np.float32)
        if self.values.ndim != 4 or self.values.shape[:3] != GRID_SHAPE:
            raise SpecGenError(f"table values must have shape (90, 90, 180, C), got {self.values.shape}")
        n = self.values.shape[3]
        if self.wavelengths is not None:
            self.wavelengths = np.asarray(self.wavelengths, dtype=np.float64)
            if (self.wavelengths.shape != (n,) or not np.all(np.isfinite(self.wavelengths))
                    or np.any(np.diff(self.wavelengths) <= 0)):
                raise SpecGenError("wavelengths must be finite and increasing (nm), one per column")
            if not self.channels:
                self.channels = tuple(f"{w:g}nm" for w in self.wavelengths)
        elif not self.channels:
            self.channels = ("R", "G", "B") if n == 3 else tuple(f"c{i}" for i in range(n))
        if len(self.channels) != n:
            raise SpecGenError(f"{len(self.channels)} channel names for {n} columns")
        self.metadata = {"units": "1/sr", **dict(self.metadata)}

    # ------------------------------------------------------------------ properties
    @property
    def is_spectral(self) -> bool:
        return self.wavelengths is not None

    @property
    def n_channels(self) -> int:
        return int(self.values.shape[3])

    # ------------------------------------------------------------------ evaluation
    def eval_hd(self, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
        """Trilinear lookup at Rusinkiewicz angles (radians) → ``(N, C)``; φd wraps with period π."""
        th = np.ravel(theta_h)
        td = np.ravel(theta_d)
        pd = np.ravel(phi_d)
        i0, i1, ti = _linear_weights(theta_h_index(th), N_THETA_H, periodic=False)
        j0, j1, tj = _linear_weights(theta_d_index(td), N_THETA_D, periodic=False)
        k0, k1, tk = _linear_weights(phi_d_index(pd), N_PHI_D, periodic=True)
        flat = self.values.reshape(-1, self.n_channels)
        out = np.zeros((th.size, self.n_channels), dtype=np.float64)
        for a, wa in ((i0, 1 - ti), (i1, ti)):
            for b, wb in ((j0, 1 - tj), (j1, tj)):
                w_ab = wa * wb
                base = (a * N_THETA_D + b) * N_PHI_D
                out += (w_ab * (1 - tk))[:, None] * flat[base + k0]
                out += (w_ab * tk)[:, None] * flat[base + k1]
        return out

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray | None = None) -> np.ndarray:
        """``f_r(wi, wo[, λ])`` in sr⁻¹, shape ``(N, C)`` or ``(N, Λ)``; zero below the horizon.

        ``wi``/``wo`` are unit vectors (…, 3) in the local frame (normal +z). With
        ``wavelengths_nm`` a spectral table is interpolated linearly in λ (nm, inside its range).
        """
        wi = np.asarray(wi, dtype=np.float64).reshape(-1, 3)
        wo = np.asarray(wo, dtype=np.float64).reshape(-1, 3)
        vals = self.eval_hd(*half_diff_from_io(wi, wo))
        if wavelengths_nm is not None:
            vals = vals @ self.wavelength_weights(wavelengths_nm)
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        return np.where(above[:, None], np.maximum(vals, 0.0), 0.0)

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Linear sRGB ``f_r`` (N, 3): the RGB columns, or the spectrum projected under D65."""
        if self.is_spectral:
            return reflectance_to_linear_srgb(self.eval(wi, wo), self.wavelengths)
        return self.eval(wi, wo)

    def wavelength_weights(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """Matrix ``(C, Λ)`` that linearly interpolates this table's spectra at ``wavelengths_nm``."""
        if not self.is_spectral:
            raise SpecGenError("an RGB table has no wavelength axis; use eval_rgb")
        w = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        lo, hi = self.wavelengths[0], self.wavelengths[-1]
        if w.size == 0 or not np.all(np.isfinite(w)):
            raise SpecGenError(f"wavelengths must be finite numbers (nm), got {w.tolist()}")
        if np.any(w < lo - 1e-6) or np.any(w > hi + 1e-6):
            raise SpecGenError(f"wavelengths {w.min():g}–{w.max():g} nm fall outside the table's "
                               f"{lo:g}–{hi:g} nm")
        return spectra.interpolation_matrix(self.wavelengths, w)

    # ------------------------------------------------------------------ construction
    @classmethod
    def tabulate(cls, fn: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
                 wavelengths: np.ndarray | None = None, channels: Sequence[str] = (),
                 metadata: dict | None = None, progress: ProgressFn | None = None,
                 cancel: CancelFn | None = None, rows_per_chunk: int = 6) -> "BRDFTable":
        """Fill the grid with ``fn(theta_h, theta_d, phi_d) -> (N, C)`` (radians), chunked by θh rows.

        ``progress(fraction)`` is called after each chunk; ``cancel()`` returning True raises
        :class:`~specgen_addon.common.errors.Cancelled`.
        """
        th, td, pd = grid_angles()
        TD, PD = np.meshgrid(td, pd, indexing="ij")
        values = None
        for start in range(0, N_THETA_H, rows_per_chunk):
            if cancel is not None and cancel():
                raise Cancelled("tabulation cancelled")
            rows = th[start:start + rows_per_chunk]
            TH = np.repeat(rows, TD.size)
            out = np.asarray(fn(TH, np.tile(TD.ravel(), rows.size), np.tile(PD.ravel(), rows.size)))
            out = out.reshape(rows.size, N_THETA_D, N_PHI_D, -1)
            if values is None:
                values = np.empty(GRID_SHAPE + (out.shape[-1],), dtype=np.float32)
            values[start:start + rows.size] = out
            if progress is not None:
                progress(min(1.0, (start + rows.size) / N_THETA_H))
        return cls(values, wavelengths, tuple(channels), dict(metadata or {}))

    def to_rgb(self, illuminant: str = "D65") -> "BRDFTable":
        """RGB projection of a spectral table (linear sRGB BRDF under ``illuminant``)."""
        if not self.is_spectral:
            return self

        rgb = reflectance_to_linear_srgb(self.values.reshape(-1, self.n_channels), self.wavelengths,
                                         illuminant).reshape(GRID_SHAPE + (3,))
        meta = {**self.metadata, "projected_from": "spectral", "illuminant": illuminant}
        return BRDFTable(rgb.astype(np.float32), None, ("R", "G", "B"), meta)

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | Path, overwrite: bool = False, compact: bool = False) -> Path:
        """Write an ``.npz`` (values float32, wavelengths, channels, metadata JSON), atomically;
        ``compact``: the compact material file instead (:mod:`specgen_addon.brdf.material_file`, a few MB,
        values kept to ±0.2 %), which :meth:`load` reads the same way."""
        path = Path(path)
        if path.suffix != ".npz":
            raise SpecGenError(f"{path}: table files use the .npz suffix")
        if compact:
            return save_compact(self, path, overwrite=overwrite)
        header = {"format": TABLE_FORMAT, "version": TABLE_FORMAT_VERSION,
                  "channels": list(self.channels), "metadata": self.metadata}
        with atomic_write(path, overwrite=overwrite) as tmp:
            write_npz(tmp, values=self.values,
                      wavelengths=(self.wavelengths if self.is_spectral else np.zeros(0)),
                      header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "BRDFTable":
        """Read a table written by :meth:`save`; raises :class:`BRDFFormatError` on bad files."""
        path = Path(path)
        if path.is_dir():
            raise BRDFFormatError(path, "is a folder, expected a SpecGen table (.npz)")
        if not path.is_file():
            raise BRDFFormatError(path, "no such file")
        try:
            with np.load(path, allow_pickle=False) as z:
                header = json.loads(bytes(z["header"]).decode())
                if isinstance(header, dict) and header.get("format") == COMPACT_FORMAT:
                    values, wavelengths = load_compact(path, header, z)
                    header = {**header, "format": TABLE_FORMAT, "version": TABLE_FORMAT_VERSION}
                else:
                    values = z["values"]
                    wavelengths = z["wavelengths"]
        except PermissionError:
            raise BRDFFormatError(path, "cannot read file (permission denied)") from None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, AttributeError) as exc:
            raise BRDFFormatError(path, f"not a readable SpecGen table ({type(exc).__name__}: {exc})") from None
        if not isinstance(header, dict):
            raise BRDFFormatError(path, "not a SpecGen BRDF table (bad header)")
        if header.get("format") != TABLE_FORMAT:
            raise BRDFFormatError(path, "not a SpecGen BRDF table")
        if header.get("version") != TABLE_FORMAT_VERSION:
            raise BRDFFormatError(path, f"unsupported table version {header.get('version')}")

        reason = bad_values(values) if values.dtype.kind == "f" else f"values of type {values.dtype}"
        if reason:
            raise BRDFFormatError(path, f"invalid BRDF values: {reason}")
        try:
            return cls(values, wavelengths if wavelengths.size else None,
                       tuple(header.get("channels", ())), header.get("metadata", {}))
        except SpecGenError as exc:
            raise BRDFFormatError(path, str(exc)) from None
