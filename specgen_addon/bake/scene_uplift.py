"""Per-band conversion of a Blender scene's RGB quantities for the full-scene spectral render.

The full-scene render (``ops/render_fullscene.py``) makes Cycles path-trace three bands at a
time, one per R, G, B channel. Everything Cycles multiplies or adds is per channel, so a render
whose inputs hold band values ``(x(λa), x(λb), x(λc))`` is three monochromatic renders at once.
This module holds the numbers the Blender side writes into the scene:

* **Reflectances and textures** (BSDF colours, image textures): the linear RGB→spectrum basis of
  Mallett & Yuksel (2019), "Spectral Primary Decomposition for Rendering with sRGB Reflectance",
  EGSR: ``ρ(λ) = Σ_c rgb_c M_c(λ)``. Being linear, a texture stays a texture: band ``λ`` of a
  texel is ``dot(M(λ), rgb)``, three dot products per band group in a node.
* **Emitters** (light colours, Emission and Background colours, environment maps): the same basis
  times D65 of unit luminance, ``L(λ) = Σ_c rgb_c M_c(λ) D65(λ)`` — the convention of the exact
  mode and the reference renderer (:func:`specgen_addon.render.environment.uplift_basis`), so a
  white light of strength E is D65 light of luminance E in both modes.
* **Blackbody** temperatures (Blackbody node, light temperature): Planck's law normalised to unit
  luminance on the band grid, as Blender normalises its Blackbody RGB to unit luminance.

Band groups: bands are taken three at a time in order; the last group repeats its final band
when Λ is not a multiple of three. Wavelengths in nm, temperatures in kelvin.
"""

from __future__ import annotations

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.environment import uplift_basis

#: Planck's second radiation constant c₂ = h c / k_B (m·K).
PLANCK_C2_M_K = 1.438776877e-2


def emission_basis(wavelengths_nm: np.ndarray) -> np.ndarray:
    """``U`` (3, Λ): emitted spectral radiance ``L(λ) = rgb @ U`` for linear-sRGB radiance ``rgb``."""
    return uplift_basis(np.asarray(wavelengths_nm, np.float64))


def reflectance_basis(wavelengths_nm: np.ndarray) -> np.ndarray:
    """``M`` (3, Λ): reflectance ``ρ(λ) = rgb @ M`` for a linear-sRGB albedo (Mallett & Yuksel 2019).

    The emission basis divided by the D65 it was multiplied with (D65 > 0 on 300–830 nm).
    """
    w = np.asarray(wavelengths_nm, np.float64)
    d65 = spectra.illuminant_spd("D65", w)
    if np.any(d65 <= 0):
        raise SpecGenError(f"D65 is zero somewhere on {w.min():g}–{w.max():g} nm; no reflectance basis")
    return emission_basis(w) / d65[None, :]


def blackbody_spectrum(temperature_k: float, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Planck spectral radiance at ``temperature_k`` on the grid, scaled to unit luminance
    (``Σ B ȳ Δλ / Σ ȳ Δλ = 1``, :func:`specgen_addon.spectral.spectra.illuminant_spd`'s normalisation)."""
    t = float(temperature_k)
    if not t > 0:
        raise SpecGenError(f"blackbody temperature must be positive, got {t:g} K")
    w = np.asarray(wavelengths_nm, np.float64)
    lam_m = w * 1e-9
    with np.errstate(over="ignore"):
        b = 1.0 / (lam_m ** 5 * np.expm1(PLANCK_C2_M_K / (lam_m * t)))
    ybar = spectra.cmfs(w)[:, 1]
    dl = spectra.band_widths(w)
    norm = np.sum(b * ybar * dl) / np.sum(ybar * dl)
    if not np.isfinite(norm) or norm <= 0:
        norm = float(np.mean(b)) or 1.0
    return b / norm


def band_groups(n_bands: int) -> np.ndarray:
    """(G, 3) band indices rendered together in R, G, B; the last group repeats its final band."""
    if n_bands < 1:
        raise SpecGenError(f"need at least one band, got {n_bands}")
    idx = np.arange(-(-n_bands // 3) * 3)
    return np.minimum(idx, n_bands - 1).reshape(-1, 3)


def group_values(spectrum: np.ndarray, group: np.ndarray) -> tuple[float, float, float]:
    """The (R, G, B) a render of band group ``group`` uses for a per-band quantity ``spectrum`` (Λ,)."""
    s = np.asarray(spectrum, np.float64)
    return tuple(float(s[i]) for i in group)


def group_matrix(basis: np.ndarray, group: np.ndarray) -> np.ndarray:
    """(3, 3) matrix taking an RGB colour to a render's three band values: row j = ``basis[:, group[j]]``."""
    return np.asarray(basis, np.float64)[:, np.asarray(group)].T.copy()


def unpack_groups(images: np.ndarray, n_bands: int) -> np.ndarray:
    """Band-group renders (G, H, W, 3) → spectral image (H, W, Λ) (padding bands dropped)."""
    g, h, w, _ = images.shape
    if g != band_groups(n_bands).shape[0]:
        raise SpecGenError(f"{g} band-group images for {n_bands} bands")
    return np.moveaxis(images, 0, 2).reshape(h, w, 3 * g)[:, :, :n_bands].copy()
