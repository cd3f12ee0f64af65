"""Equirectangular HDR environment lighting: loading, RGB → spectrum uplifting, importance sampling.

Direction convention (matches Blender's world texture so Cycles renders can be compared): the
renderer's world frame (+x right, +y up, +z towards the camera) maps to Blender's (z-up) as
``(x, y, z) → (x, −z, y)``, i.e. the default camera is Blender's front view (at −Y looking +Y).
A direction with azimuth ``φ = atan2(z, x)`` and elevation ``el = asin(y)`` reads the texel at
``u = φ / 2π + 1/2`` (column, left to right) and ``v = el / π + 1/2`` (bottom to top), Blender's
``direction_to_equirectangular``. ``rotation_rad`` turns the map about the up axis (+y).

Spectra: environment texels are linear sRGB. They are uplifted linearly so that integration can stay
in RGB until the last step: ``L(λ) = Σ_c rgb_c · U_c(λ)``, where ``U`` is either

* ``"mallett2019"``: the three sRGB basis reflectances of Mallett & Yuksel (2019), "Spectral
  Primary Decomposition for Rendering with sRGB Reflectance", EGSR, as shipped by colour-science
  (``colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019``), times the D65 SPD (unit luminance),
  so a white texel (1, 1, 1) is D65 light of unit luminance; or
* the name of a CIE illuminant: texel luminance ``Y`` times that illuminant's SPD (colour dropped).

Importance sampling draws texels with probability ∝ luminance · cos(el) (the solid angle of an
equirect texel), and directions uniformly inside the texel (Pharr, Jakob & Humphreys, PBRT 4e,
§12.5 "Image infinite lights").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.rgb_to_spectrum import rgb_to_spectrum
from specgen_addon.common.image_io import ImageIOError, read_exr, read_float_image
from specgen_addon.spectral.colour_tables import tables

MALLETT2019 = "mallett2019"
#: Rec. 709 / sRGB luminance weights (row Y of the sRGB → XYZ matrix), from colour-science.
_SRGB_Y_WEIGHTS: np.ndarray | None = None


def srgb_luminance_weights() -> np.ndarray:
    """(3,) weights giving CIE Y from linear sRGB (colour-science's sRGB matrix)."""
    global _SRGB_Y_WEIGHTS
    if _SRGB_Y_WEIGHTS is None:
        _SRGB_Y_WEIGHTS = np.asarray(tables()["srgb_rgb_to_xyz"][1], float)
    return _SRGB_Y_WEIGHTS


@functools.lru_cache(maxsize=32)
def _uplift_basis_cached(method: str, key: tuple[float, ...]) -> np.ndarray:
    w = np.asarray(key)
    if method == MALLETT2019:
        # colour-science's basis, precomputed (specgen_addon.spectral.colour_tables): the uplifts of
        # the three sRGB primaries. Outside its 380–780 nm support the nearest value is held (a
        # smooth continuation of the flat reflectance that white uplifts to).
        return rgb_to_spectrum(np.eye(3), w, method="Mallett 2019") * spectra.illuminant_spd("D65", w)[None, :]
    return srgb_luminance_weights()[:, None] * spectra.illuminant_spd(method, w)[None, :]


def uplift_basis(wavelengths_nm: np.ndarray, method: str = MALLETT2019) -> np.ndarray:
    """Matrix ``U`` (3, Λ) with spectral radiance ``L(λ) = rgb @ U`` for linear-sRGB radiance ``rgb``."""
    return _uplift_basis_cached(method, tuple(float(x) for x in np.atleast_1d(wavelengths_nm))).copy()


def read_exr_rgb(path: str | Path) -> np.ndarray:
    """Read the R, G, B channels of an OpenEXR file as float32 (H, W, 3), row 0 on top
    (OpenEXR, or Blender's bundled OpenImageIO: :mod:`specgen_addon.common.image_io`)."""
    path = Path(path)
    if not path.is_file():
        raise SpecGenError(f"{path}: environment map not found")
    try:
        channels, _ = read_exr(path)
    except ImageIOError as exc:
        raise SpecGenError(str(exc)) from None   # names the file and what is wrong
    if not all(c in channels for c in "RGB"):
        raise SpecGenError(f"{path}: EXR has no R, G, B channels (has {sorted(channels)})")
    return np.stack([channels[c] for c in "RGB"], -1)


def read_hdr_rgb(path: str | Path) -> np.ndarray:
    """Read a Radiance ``.hdr`` (RGBE) file as float32 (H, W, 3), row 0 on top, via OpenImageIO
    (bundled with Blender, so this also works inside a stock Blender)."""
    path = Path(path)
    if not path.is_file():
        raise SpecGenError(f"{path}: environment map not found")
    px = read_float_image(path, SpecGenError, "Radiance HDR")
    if px.shape[2] < 3:
        raise SpecGenError(f"{path}: Radiance HDR has no RGB pixels")
    return np.ascontiguousarray(px[..., :3], dtype=np.float32)


def direction_to_uv(d: np.ndarray, rotation_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """World directions (…, 3) → equirect (u, v) in [0, 1], v = 0 at the bottom (nadir)."""
    phi = np.arctan2(d[..., 2], d[..., 0]) - rotation_rad
    u = np.mod(phi / (2.0 * np.pi) + 0.5, 1.0)
    v = np.arcsin(np.minimum(np.maximum(d[..., 1], -1.0), 1.0)) / np.pi + 0.5
    return u, v


def uv_to_direction(u: np.ndarray, v: np.ndarray, rotation_rad: float = 0.0) -> np.ndarray:
    """Inverse of :func:`direction_to_uv`: unit world directions (…, 3)."""
    phi = (u - 0.5) * 2.0 * np.pi + rotation_rad
    el = (v - 0.5) * np.pi
    c = np.cos(el)
    return np.stack([c * np.cos(phi), np.sin(el), c * np.sin(phi)], axis=-1)


def _box_downsample(rgb: np.ndarray, max_width: int) -> np.ndarray:
    """Halve an equirect map (2×2 box) until it is at most ``max_width`` wide (or odd-sized)."""
    while rgb.shape[1] > max_width and rgb.shape[0] % 2 == 0 and rgb.shape[1] % 2 == 0:
        h, w = rgb.shape[0] // 2, rgb.shape[1] // 2
        rgb = rgb.reshape(h, 2, w, 2, 3).mean(axis=(1, 3))
    return rgb


def _texel_directions(h: int, w: int, rotation_rad: float) -> np.ndarray:
    """World directions (h, w, 3) of the texel centres of an h×w equirect map."""
    uu, vv = np.meshgrid((np.arange(w) + 0.5) / w, 1.0 - (np.arange(h) + 0.5) / h)
    return uv_to_direction(uu, vv, rotation_rad)


def _bilinear_equirect(table: np.ndarray, d: np.ndarray, rotation_rad: float) -> np.ndarray:
    """Bilinear lookup of an equirect table (h, w, C) at directions (…, 3); u wraps, v clamps."""
    h, w = table.shape[:2]
    u, v = direction_to_uv(d, rotation_rad)
    fx, fy = u * w - 0.5, (1.0 - v) * h - 0.5
    x0, y0 = np.floor(fx), np.floor(fy)
    tx, ty = (fx - x0)[..., None], (fy - y0)[..., None]
    x0 = x0.astype(np.int64) % w
    x1 = (x0 + 1) % w
    y1 = np.clip(y0.astype(np.int64) + 1, 0, h - 1)
    y0 = np.clip(y0.astype(np.int64), 0, h - 1)
    top = table[y0, x0] * (1 - tx) + table[y0, x1] * tx
    bottom = table[y1, x0] * (1 - tx) + table[y1, x1] * tx
    return top * (1 - ty) + bottom * ty


@dataclass
class Environment:
    """An equirectangular environment: linear-sRGB radiance texels plus how to make spectra of them.

    Parameters
    ----------
    rgb
        (H, W, 3) linear sRGB radiance in W·m⁻²·sr⁻¹ (relative), row 0 = zenith side.
    rotation_rad
        Rotation of the map about the world up axis (+y), radians.
    uplift
        ``"mallett2019"`` or a CIE illuminant name (see module docstring).
    name
        Label for reports.
    """

    rgb: np.ndarray
    rotation_rad: float = 0.0
    uplift: str = MALLETT2019
    name: str = "environment"
    _pdf: tuple | None = field(default=None, init=False, repr=False)
    _irradiance: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        rgb = np.asarray(self.rgb, dtype=np.float32)
        if rgb.ndim != 3 or rgb.shape[-1] != 3 or rgb.shape[0] < 2 or rgb.shape[1] < 2:
            raise SpecGenError(f"environment map must be H×W×3, got shape {rgb.shape}")
        if not np.all(np.isfinite(rgb)):
            raise SpecGenError(f"environment map {self.name!r} holds NaN or Inf values")
        self.rgb = np.clip(rgb, 0.0, None)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_file(cls, path: str | Path, exposure: float = 1.0, rotation_rad: float = 0.0,
                  normalise: bool = True, uplift: str = MALLETT2019,
                  max_width: int | None = 512) -> "Environment":
        """Load an equirect EXR (or Radiance ``.hdr``).

        ``normalise`` scales the map to unit mean luminance over the sphere (solid-angle weighted),
        so different maps light a white Lambertian at comparable levels; ``exposure`` multiplies
        after that. ``max_width`` box-downsamples large maps (by powers of two) for speed.
        """
        rgb = read_hdr_rgb(path) if Path(path).suffix.lower() == ".hdr" else read_exr_rgb(path)
        if max_width is not None:
            rgb = _box_downsample(rgb, max_width)
        env = cls(rgb, rotation_rad=rotation_rad, uplift=uplift, name=Path(path).stem)
        scale = exposure / env.mean_luminance() if normalise else exposure
        env.rgb = env.rgb * np.float32(scale)
        return env

    @classmethod
    def uniform(cls, rgb: tuple[float, float, float] = (1.0, 1.0, 1.0), size: tuple[int, int] = (8, 16),
                uplift: str = MALLETT2019) -> "Environment":
        """Constant radiance in every direction (the white-furnace environment)."""
        return cls(np.broadcast_to(np.asarray(rgb, np.float32), (*size, 3)).copy(), uplift=uplift,
                   name="uniform")

    def with_(self, exposure: float = 1.0, rotation_rad: float | None = None) -> "Environment":
        """A copy scaled by ``exposure`` and optionally re-rotated (for lighting augmentation)."""
        return Environment(self.rgb * np.float32(exposure),
                           self.rotation_rad if rotation_rad is None else rotation_rad,
                           self.uplift, self.name)

    # -- statistics ---------------------------------------------------------------------------
    def _texel_cos_el(self) -> np.ndarray:
        h = self.rgb.shape[0]
        v = 1.0 - (np.arange(h) + 0.5) / h
        return np.cos((v - 0.5) * np.pi)

    def luminance(self) -> np.ndarray:
        """(H, W) luminance Y of the texels."""
        return self.rgb @ srgb_luminance_weights().astype(np.float32)

    def mean_luminance(self) -> float:
        """Solid-angle-weighted mean luminance over the sphere (≈ irradiance / π of a white floor)."""
        w = self._texel_cos_el()[:, None]
        mean = float(np.sum(self.luminance() * w) / (np.sum(w) * self.rgb.shape[1]))
        if mean <= 0:
            raise SpecGenError(f"environment map {self.name!r} is black")
        return mean

    def spectral_basis(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """(3, Λ) uplifting matrix of this environment (see :func:`uplift_basis`)."""
        return uplift_basis(wavelengths_nm, self.uplift)

    def irradiance_rgb(self, normals: np.ndarray) -> np.ndarray:
        """Irradiance ``E(n) = ∫ L(ω) (n·ω)⁺ dω`` (…, 3) for world normals (…, 3).

        ``E`` is smooth in ``n``, so it is tabulated once per environment on a 128×64 equirect grid
        of normals (quadrature over the map box-filtered to 128×64 texels, exact texel solid
        angles) and interpolated bilinearly.
        """
        if self._irradiance is None:
            rgb = _box_downsample(self.rgb, 128)
            h, w = rgb.shape[:2]
            dirs = _texel_directions(h, w, self.rotation_rad).reshape(-1, 3)
            # exact solid angle of a texel row: (2π/W)·(sin el_top − sin el_bottom)
            edges = (0.5 - np.arange(h + 1) / h) * np.pi
            d_omega = (2.0 * np.pi / w) * (np.sin(edges[:-1]) - np.sin(edges[1:]))
            weighted = (rgb.astype(np.float64) * d_omega[:, None, None]).reshape(-1, 3)
            grid = _texel_directions(64, 128, self.rotation_rad).reshape(-1, 3)
            table = np.empty((grid.shape[0], 3))
            for start in range(0, grid.shape[0], 1024):
                table[start:start + 1024] = np.maximum(grid[start:start + 1024] @ dirs.T, 0.0) @ weighted
            self._irradiance = table.reshape(64, 128, 3)
        return _bilinear_equirect(self._irradiance, np.asarray(normals, dtype=np.float64), self.rotation_rad)

    # -- sampling -----------------------------------------------------------------------------
    def _distribution(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._pdf is None:
            h, w = self.rgb.shape[:2]
            weight = self.luminance().astype(np.float64) * self._texel_cos_el()[:, None]
            if weight.sum() <= 0:
                weight = np.ones_like(weight) * self._texel_cos_el()[:, None]
            p = weight / weight.sum()
            row = p.sum(axis=1)
            cdf_row = np.concatenate([[0.0], np.cumsum(row)])
            cdf_row /= cdf_row[-1]
            cond = p / np.where(row > 0, row, 1.0)[:, None]
            cdf_col = np.concatenate([np.zeros((h, 1)), np.cumsum(cond, axis=1)], axis=1)
            cdf_col /= np.where(cdf_col[:, -1:] > 0, cdf_col[:, -1:], 1.0)
            self._pdf = (p, cdf_row, cdf_col)
        return self._pdf

    def _texel_index(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, w = self.rgb.shape[:2]
        u, v = direction_to_uv(d, self.rotation_rad)
        col = np.minimum((u * w).astype(np.int64), w - 1)
        row = np.minimum(((1.0 - v) * h).astype(np.int64), h - 1)
        return row, col

    def radiance_rgb(self, d: np.ndarray) -> np.ndarray:
        """Linear-sRGB radiance (…, 3) arriving from world directions ``d`` (…, 3), nearest texel."""
        row, col = self._texel_index(d)
        return self.rgb[row, col]

    def pdf(self, d: np.ndarray) -> np.ndarray:
        """Solid-angle density (sr⁻¹) of :meth:`sample` at world directions ``d`` (…, 3)."""
        p = self._distribution()[0]
        h, w = p.shape
        row, col = self._texel_index(d)
        cos_el = np.sqrt(np.maximum(1.0 - d[..., 1] ** 2, 0.0))
        return p[row, col] * (h * w) / (2.0 * np.pi ** 2 * np.maximum(cos_el, 1e-9))

    def sample(self, xi: np.ndarray) -> np.ndarray:
        """Map uniforms ``xi`` (…, 2) in [0, 1)² to world directions ∝ luminance (inverse CDF)."""
        _, cdf_row, cdf_col = self._distribution()
        h, w = cdf_col.shape[0], cdf_col.shape[1] - 1
        x1, x2 = xi[..., 0].ravel(), xi[..., 1].ravel()
        row = np.clip(np.searchsorted(cdf_row, x1, side="right") - 1, 0, h - 1)
        lo, hi = cdf_row[row], cdf_row[row + 1]
        fv = np.minimum(np.maximum((x1 - lo) / np.maximum(hi - lo, 1e-300), 0.0), 1.0 - 1e-9)
        # Conditional column CDFs searched at once: row r's CDF is offset by r (monotone overall).
        flat = (cdf_col + np.arange(h)[:, None]).ravel()
        pos = np.searchsorted(flat, x2 + row, side="right") - 1
        col = np.clip(pos - row * (w + 1), 0, w - 1)
        lo, hi = cdf_col[row, col], cdf_col[row, col + 1]
        fu = np.minimum(np.maximum((x2 - lo) / np.maximum(hi - lo, 1e-300), 0.0), 1.0 - 1e-9)
        u = (col + fu) / w
        v = 1.0 - (row + fv) / h
        return uv_to_direction(u, v, self.rotation_rad).reshape(*xi.shape[:-1], 3)
