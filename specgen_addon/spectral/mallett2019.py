"""Reflectance spectra from linear sRGB: Mallett & Yuksel (2019), in numpy.

"Spectral Primary Decomposition for Rendering with sRGB Reflectance" (EGSR 2019): every linear-sRGB
colour in [0, 1]³ is the linear combination of three basis reflectances (the sRGB primaries'
uplifts, which sum to 1), so the uplift is linear and white gives the flat reflectance:

    R(λ) = r · B_r(λ) + g · B_g(λ) + b · B_b(λ).

This is colour-science's ``colour.recovery.RGB_to_sd_Mallett2019`` on the basis it ships
(``MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019``, precomputed into ``data/colour_tables.npz``:
:func:`specgen_addon.spectral.colour_tables.mallett2019_basis`).
"""

from __future__ import annotations

import numpy as np

from specgen_addon.spectral.colour_tables import mallett2019_basis


def mallett2019_reflectance(rgb: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """The Mallett 2019 reflectance (…, Λ) of linear-sRGB colours ``rgb`` (…, 3) at ``wavelengths_nm``
    (nm); the basis' nearest value is held outside 380–780 nm."""
    return np.asarray(rgb, dtype=np.float64) @ mallett2019_basis(wavelengths_nm).T
