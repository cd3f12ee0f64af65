"""RGB → spectrum: one dispatcher over the uplifting methods, as colour-science's
``colour.recovery.RGB_to_sd(method=…)`` and ``XYZ_to_sd(method=…)``.

One module per method:

* ``"Otsu 2018"`` (:mod:`specgen_addon.spectral.otsu2018`): Otsu, Yamamoto & Hachisuka, measured
  reflectances clustered by chromaticity; exact CIE XYZ under D65, a natural-looking spectrum.
* ``"Mallett 2019"`` (:mod:`specgen_addon.spectral.mallett2019`): Mallett & Yuksel, linear in
  the colour (three basis reflectances); what lights and environment texels are uplifted with.

Colours are linear sRGB (D65 white, Y of white = 1) or CIE XYZ under D65 (Y of white = 1);
spectra are reflectances on ``wavelengths_nm`` (nm).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.colour_tables import tables
from specgen_addon.spectral.mallett2019 import mallett2019_reflectance
from specgen_addon.spectral.otsu2018 import otsu2018_reflectance


def _otsu2018_rgb(rgb: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    return _otsu2018_xyz(rgb @ _rgb_to_xyz().T, wavelengths_nm)


def _otsu2018_xyz(xyz: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim == 1:
        return otsu2018_reflectance(xyz, wavelengths_nm)
    flat = [otsu2018_reflectance(c, wavelengths_nm) for c in xyz.reshape(-1, 3)]
    return np.stack(flat).reshape(*xyz.shape[:-1], -1)


def _mallett2019_xyz(xyz: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    return mallett2019_reflectance(np.asarray(xyz, np.float64) @ np.linalg.inv(_rgb_to_xyz()).T, wavelengths_nm)


def _rgb_to_xyz() -> np.ndarray:
    """(3, 3) linear sRGB → CIE XYZ (D65, Y of white = 1), colour-science's matrix."""
    return np.asarray(tables()["srgb_rgb_to_xyz"], np.float64)


#: method name → (from linear sRGB, from CIE XYZ), each ``f(colour (…, 3), wavelengths_nm) -> (…, Λ)``
RGB_TO_SPECTRUM_METHODS: dict[str, tuple[Callable[..., np.ndarray], Callable[..., np.ndarray]]] = {
    "Otsu 2018": (_otsu2018_rgb, _otsu2018_xyz),
    "Mallett 2019": (mallett2019_reflectance, _mallett2019_xyz),
}


def _method(method: str) -> tuple[Callable[..., np.ndarray], Callable[..., np.ndarray]]:
    try:
        return RGB_TO_SPECTRUM_METHODS[method]
    except KeyError:
        raise SpecGenError(f"unknown RGB to spectrum method {method!r}; known: "
                           f"{', '.join(RGB_TO_SPECTRUM_METHODS)}") from None


def rgb_to_spectrum(rgb: np.ndarray, wavelengths_nm: np.ndarray, method: str = "Otsu 2018") -> np.ndarray:
    """Reflectance spectra (…, Λ) of linear-sRGB colours ``rgb`` (…, 3) by ``method`` (one of
    :data:`RGB_TO_SPECTRUM_METHODS`), at ``wavelengths_nm`` (nm)."""
    return _method(method)[0](np.asarray(rgb, dtype=np.float64), wavelengths_nm)


def xyz_to_spectrum(xyz: np.ndarray, wavelengths_nm: np.ndarray, method: str = "Otsu 2018") -> np.ndarray:
    """Reflectance spectra (…, Λ) of CIE XYZ colours ``xyz`` (…, 3; D65, Y of white = 1) by
    ``method`` (one of :data:`RGB_TO_SPECTRUM_METHODS`), at ``wavelengths_nm`` (nm)."""
    return _method(method)[1](xyz, wavelengths_nm)
