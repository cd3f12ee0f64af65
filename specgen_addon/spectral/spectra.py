"""Spectral maths: wavelength grids, CIE 1931 CMFs, illuminants, spectrum → XYZ → linear sRGB.

Everything colorimetric comes from colour-science (``colour.MSDS_CMFS``, ``colour.SDS_ILLUMINANTS``,
``colour.RGB_COLOURSPACES['sRGB']``, Bradford adaptation) through the tables it generates at build
time (:mod:`specgen_addon.spectral.colour_tables`), so this module runs with numpy alone (inside a stock
Blender); nothing is hand-typed. Tests check it against colour-science itself.

Conventions (used by the renderer, the corpus and the Blender side alike):

* Wavelengths are in nanometres. Spectral radiance images ``L(λ)`` are in W·m⁻²·sr⁻¹·nm⁻¹ up to a
  global scale.
* Lights carry ``E · illuminant_spd(name, λ)`` where :func:`illuminant_spd` is normalised to unit
  luminance (``Σ S ȳ / Σ ȳ = 1``), so a white Lambertian under unit light has ``Y = 1``.
* :func:`spectral_to_xyz` is the emissive integral ``XYZ = Σ L x̄ Δλ / Σ ȳ Δλ`` on the given grid.
"""

from __future__ import annotations

import functools

import numpy as np

from specgen_addon.spectral import colour_tables
from specgen_addon.common.errors import SpecGenError

#: Range the spectral machinery accepts (the RGL spectral measurements span 360–1000 nm).
MIN_WAVELENGTH_NM = 360.0
MAX_WAVELENGTH_NM = 1000.0
#: The CIE visible range used by default.
DEFAULT_RANGE_NM = (380.0, 780.0)
DEFAULT_BAND_COUNT = 21
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
DEFAULT_ILLUMINANT = "D65"


def wavelength_grid(start_nm: float = DEFAULT_RANGE_NM[0], end_nm: float = DEFAULT_RANGE_NM[1],
                    count: int = DEFAULT_BAND_COUNT) -> np.ndarray:
    """Evenly spaced band centres in nm, inclusive of both ends, within 360–1000 nm."""
    if count < 1:
        raise SpecGenError(f"band count must be at least 1, got {count}")
    if not (MIN_WAVELENGTH_NM <= start_nm <= end_nm <= MAX_WAVELENGTH_NM):
        raise SpecGenError(
            f"wavelength range {start_nm}–{end_nm} nm must lie within "
            f"{MIN_WAVELENGTH_NM:g}–{MAX_WAVELENGTH_NM:g} nm with start ≤ end")
    if count > 1 and start_nm == end_nm:
        raise SpecGenError("a grid of several bands needs start < end")
    return np.linspace(start_nm, end_nm, count) if count > 1 else np.array([start_nm], float)


DEFAULT_WAVELENGTHS_NM = wavelength_grid()


def interpolation_matrix(from_nm: np.ndarray, to_nm: np.ndarray) -> np.ndarray:
    """(len(from_nm), len(to_nm)) matrix ``M`` with ``values @ M`` = spectra sampled at ``from_nm``
    interpolated linearly in λ onto ``to_nm`` (held constant beyond the ends, as ``np.interp``)."""
    src = np.asarray(from_nm, dtype=np.float64)
    eye = np.eye(src.size)
    return np.stack([np.interp(np.asarray(to_nm, dtype=np.float64), src, eye[c]) for c in range(src.size)])


def band_widths(wavelengths_nm: np.ndarray) -> np.ndarray:
    """Trapezoid-free band widths Δλ (nm) of a sorted grid: half the distance to each neighbour."""
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    if w.size == 1:
        return np.ones(1)
    edges = np.concatenate([[w[0] - (w[1] - w[0]) / 2], (w[1:] + w[:-1]) / 2,
                            [w[-1] + (w[-1] - w[-2]) / 2]])
    return np.diff(edges)


@functools.lru_cache(maxsize=32)
def _cmfs_cached(key: tuple[float, ...]) -> np.ndarray:
    t = colour_tables.tables()
    w = np.asarray(key)
    # CMFs are zero outside their tabulated 360–830 nm support.
    out = np.stack([np.interp(w, t["cmfs_wavelengths_nm"], t["cmfs_values"][:, c], left=0.0, right=0.0)
                    for c in range(3)], axis=-1)
    return out


def cmfs(wavelengths_nm: np.ndarray) -> np.ndarray:
    """CIE 1931 2° colour-matching functions x̄ ȳ z̄ sampled at ``wavelengths_nm``, shape (Λ, 3)."""
    return _cmfs_cached(tuple(float(x) for x in np.atleast_1d(wavelengths_nm))).copy()


@functools.lru_cache(maxsize=64)
def _illuminant_cached(name: str, key: tuple[float, ...]) -> np.ndarray:
    sd_wavelengths, sd_values = colour_tables.illuminant(name)
    w = np.asarray(key)
    spd = np.interp(w, sd_wavelengths, sd_values)
    ybar = _cmfs_cached(key)[:, 1]
    dl = band_widths(w)
    norm = np.sum(spd * ybar * dl) / np.sum(ybar * dl)
    if not np.isfinite(norm) or norm <= 0:  # grid outside the visible range: normalise by mean
        norm = float(np.mean(spd))
    return spd / norm


def illuminant_spd(name: str, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Relative SPD of a CIE illuminant (e.g. ``"D65"``, ``"A"``) at ``wavelengths_nm``.

    Normalised to unit luminance on the grid (``Σ S ȳ Δλ / Σ ȳ Δλ = 1``).
    """
    return _illuminant_cached(name, tuple(float(x) for x in np.atleast_1d(wavelengths_nm))).copy()


def spectral_to_xyz(values: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Emissive integral ``XYZ = Σ L x̄ Δλ / Σ ȳ Δλ`` over the last axis (length Λ)."""
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    values = np.asarray(values)
    if values.shape[-1] != w.size:
        raise SpecGenError(f"spectral axis has {values.shape[-1]} samples, grid has {w.size}")
    c = cmfs(w) * band_widths(w)[:, None]
    ysum = c[:, 1].sum()
    if ysum <= 0:
        raise SpecGenError(f"wavelength grid {w.min():g}–{w.max():g} nm has no visible response")
    return values @ (c / ysum)


@functools.lru_cache(maxsize=1)
def _xyz_to_srgb_matrix() -> np.ndarray:
    return colour_tables.tables()["srgb_xyz_to_rgb"].copy()


def xyz_to_linear_srgb(xyz: np.ndarray) -> np.ndarray:
    """CIE XYZ → linear sRGB (D65 white, no adaptation: our illuminant default is D65)."""
    return np.asarray(xyz) @ _xyz_to_srgb_matrix().T


@functools.lru_cache(maxsize=64)
def _white_balance_cached(name: str, key: tuple[float, ...]) -> np.ndarray:
    w = np.asarray(key)
    white_grid = spectral_to_xyz(illuminant_spd(name, w), w)
    return colour_tables.von_kries_bradford(white_grid / white_grid[1],
                                            colour_tables.tables()["srgb_white_xyz"])


def white_balance_matrix(wavelengths_nm: np.ndarray, illuminant: str = DEFAULT_ILLUMINANT) -> np.ndarray:
    """Bradford adaptation from ``illuminant``'s white *as integrated on this grid* to sRGB's white.

    On a coarse grid (e.g. 20 nm) the Riemann sum of D65 lands ~1 % off the sRGB white point;
    adapting from the grid's own white makes a spectrally flat reflectance exactly neutral.
    """
    return _white_balance_cached(illuminant, tuple(float(x) for x in np.atleast_1d(wavelengths_nm))).copy()


def spectral_to_linear_srgb(values: np.ndarray, wavelengths_nm: np.ndarray,
                            white: str | None = DEFAULT_ILLUMINANT) -> np.ndarray:
    """Spectral radiance (last axis Λ) → linear sRGB, emissive convention.

    ``white`` names the light the scene was lit with (its grid white maps to sRGB white, see
    :func:`white_balance_matrix`); ``None`` skips the adaptation.
    """
    xyz = spectral_to_xyz(values, wavelengths_nm)
    if white is not None:
        xyz = xyz @ white_balance_matrix(wavelengths_nm, white).T
    return xyz_to_linear_srgb(xyz)


def reflectance_to_linear_srgb(reflectance: np.ndarray, wavelengths_nm: np.ndarray,
                               illuminant: str = DEFAULT_ILLUMINANT) -> np.ndarray:
    """Reflectance or BRDF spectrum (last axis Λ) → linear sRGB under ``illuminant``.

    The illuminant's white maps to sRGB white, so a flat spectrum of value ``a`` gives ``(a, a, a)``.
    """
    return spectral_to_linear_srgb(np.asarray(reflectance) * illuminant_spd(illuminant, wavelengths_nm),
                                   wavelengths_nm, white=illuminant)


def _spow(x: np.ndarray, p: float) -> np.ndarray:
    """Sign-preserving power (colour-science's ``spow``): negative values stay negative."""
    return np.sign(x) * np.abs(x) ** p


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Linear → non-linear sRGB, IEC 61966-2-1:1999 inverse EOTF (colour-science's
    ``eotf_inverse_sRGB``, checked equal in the tests)."""
    x = np.asarray(linear, dtype=np.float64)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * _spow(x, 1 / 2.4) - 0.055)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Non-linear sRGB → linear, IEC 61966-2-1:1999 EOTF (inverse of :func:`srgb_encode`;
    colour-science's ``eotf_sRGB``, checked equal in the tests)."""
    v = np.asarray(encoded, dtype=np.float64)
    return np.where(v <= 0.0031308 * 12.92, v / 12.92, _spow((v + 0.055) / 1.055, 2.4))
