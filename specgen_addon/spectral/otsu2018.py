"""Reflectance spectra from a colour: Otsu, Yamamoto & Hachisuka (2018), in numpy.

"Reproducing spectral reflectances from tristimulus colours" (Computer Graphics Forum 37(6)):
measured reflectances are clustered by chromaticity (a kd-tree over CIE xy); each cluster holds a
mean spectrum and three principal components. A colour picks its cluster and the three weights
that give the mean plus components exactly its CIE XYZ under D65:

    R(λ) = μ_k(λ) + Σ_j w_j B_kj(λ),    XYZ[R] = XYZ,    then clipped to [0, 1].

This is colour-science's ``colour.recovery.XYZ_to_sd_Otsu2018`` on the tables it ships
(precomputed into ``data/colour_tables.npz``), written again with numpy only so that the
refinement can use it inside a stock Blender. ``tests/spectral/test_spectral_recovery.py`` checks it
against colour-science.
"""

from __future__ import annotations

import functools

import numpy as np

from specgen_addon.spectral import colour_tables
from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError


def otsu2018_cluster(xy: np.ndarray) -> int:
    """Index of the Otsu 2018 cluster of CIE ``xy`` chromaticity (the paper's kd-tree walk)."""
    selector = colour_tables.tables()["otsu2018_selector"]
    i = 0
    for _ in range(selector.shape[0] + 1):
        origin, direction, lesser, greater = selector[i]
        index = int(lesser if xy[int(direction)] <= origin else greater)
        if index >= 0:
            return index
        i = -index
    raise SpecGenError("internal: the Otsu 2018 selector tree has a cycle")


@functools.lru_cache(maxsize=1)
def _xyz_weights() -> np.ndarray:
    """(N, 3): reflectance on the Otsu grid → CIE XYZ under D65 (perfect white has Y = 1)."""
    w = colour_tables.tables()["otsu2018_wavelengths_nm"]
    c = spectra.cmfs(w) * spectra.illuminant_spd("D65", w)[:, None]
    return c / c[:, 1].sum()


def xyz_of_reflectance(reflectance: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """CIE XYZ of a reflectance (last axis Λ, on ``wavelengths_nm`` in nm) under D65, Y of white = 1."""
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    return spectra.spectral_to_xyz(np.asarray(reflectance, np.float64) * spectra.illuminant_spd("D65", w), w)


def otsu2018_reflectance(xyz: np.ndarray, wavelengths_nm: np.ndarray | None = None) -> np.ndarray:
    """The Otsu 2018 reflectance (in [0, 1]) of CIE ``xyz`` (D65, Y of white = 1).

    Returned on the method's own grid (380–730 nm, 10 nm) when ``wavelengths_nm`` is None, else
    interpolated linearly onto ``wavelengths_nm`` (nm), held constant beyond 730 nm like
    colour-science's constant extrapolation.
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(3)
    total = float(xyz.sum())
    if not np.all(np.isfinite(xyz)) or total <= 0.0:
        raise SpecGenError(f"a reflectance needs a positive CIE XYZ colour, got {xyz.tolist()}")
    t = colour_tables.tables()
    k = otsu2018_cluster(xyz[:2] / total)
    basis, mean = t["otsu2018_basis"][k], t["otsu2018_means"][k]       # (3, N), (N,)
    m = _xyz_weights()
    weights = np.linalg.solve((basis @ m).T, xyz - mean @ m)
    recovered = np.clip(mean + weights @ basis, 0.0, 1.0)
    if wavelengths_nm is None:
        return recovered
    return np.interp(np.asarray(wavelengths_nm, np.float64), t["otsu2018_wavelengths_nm"], recovered)
