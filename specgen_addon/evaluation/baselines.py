"""Per-pixel RGB → spectrum uplifting baselines (the analogue of the paper's HSI methods, §4.3).

The paper compares SpecGen with hyperspectral-image reconstruction networks (MST++, HD-Net) that
turn the RGB render of a scene into a spectral image. We use the classic uplifting methods that
colour-science ships, applied pixel by pixel to the linear-sRGB render of the *same* scene:

* ``mallett2019``: Mallett & Yuksel (2019), "Spectral Primary Decomposition for Rendering with sRGB
  Reflectance", EGSR (``colour.recovery.RGB_to_sd_Mallett2019``);
* ``smits1999``: Smits (1999), "An RGB-to-Spectrum Conversion for Reflectances", JGT
  (``colour.recovery.RGB_to_sd_Smits1999``, in its own RGB space: sRGB primaries, white E, reached
  from D65 by a Bradford adaptation so that white stays white);
* ``otsu2018``: Otsu, Yamamoto & Hachisuka (2018), "Reproducing Spectral Reflectances From
  Tristimulus Colours", CGF: a learned PCA-tree prior (``colour.recovery.XYZ_to_sd_Otsu2018``);
* ``jakob2019``: Jakob & Hanika (2019), "A Low-Dimensional Function Space for Efficient Spectral
  Upsampling", CGF (``colour.recovery.find_coefficients_Jakob2019`` + ``sd_Jakob2019``).

Radiance, not reflectance. A render's pixels are unbounded radiance. Following PBRT 4e §4.6.6
(``RGBUnboundedSpectrum``), a pixel ``rgb`` (negative parts clipped to 0) is split into a scale
``s = 2·max(rgb)`` and a chroma ``c = rgb / s`` (largest component 0.5), ``c`` is uplifted as a
reflectance ``ρ_c(λ)``, and the spectral radiance estimate is ``L(λ) = s · ρ_c(λ) · S(λ)`` with
``S`` the scene's white (D65, unit luminance; see :mod:`specgen_addon.spectral.spectra`). Linear methods
(Mallett, Smits) do not depend on this split.

Speed. Mallett 2019 is linear in RGB and is applied as one (3, Λ) matrix. The other methods cost
0.7–30 ms per colour, far too slow per pixel, so each is tabulated once on the three faces of the
chroma cube (the face where channel k holds the maximum 0.5) on an ``n × n`` grid and looked up
bilinearly. Because the RGB of a spectrum is linear in the spectrum, interpolating the tabulated
spectra reproduces the interpolated colour exactly wherever the method itself round-trips at the
grid nodes; what interpolation changes is only the spectral shape between nodes. Tables are cached
as ``.npz`` under :func:`specgen_addon.common.cache.cache_root` (Jakob 2019 takes ~30 s for
its 17 × 17 faces).
"""

from __future__ import annotations

import functools
from typing import Callable

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.cache import cache_root
from specgen_addon.common.atomic_io import atomic_write

MALLETT2019 = "mallett2019"
SMITS1999 = "smits1999"
OTSU2018 = "otsu2018"
JAKOB2019 = "jakob2019"
#: All baselines, in table order.
METHODS = (MALLETT2019, SMITS1999, OTSU2018, JAKOB2019)
LABELS = {MALLETT2019: "Mallett 2019", SMITS1999: "Smits 1999", OTSU2018: "Otsu 2018",
          JAKOB2019: "Jakob 2019"}
#: Face-grid size (nodes per side) of the tabulated methods.
LUT_SIZE = {SMITS1999: 17, OTSU2018: 17, JAKOB2019: 17}
#: Wavelengths (nm) the tabulated spectra are stored on; lookups interpolate from here.
LUT_WAVELENGTHS_NM = np.arange(380.0, 781.0, 5.0)
#: Chroma of the brightest component (PBRT 4e's RGBUnboundedSpectrum uses max = 0.5).
CHROMA_MAX = 0.5


def _colour_setup() -> tuple[object, object]:
    import colour

    cmfs = colour.MSDS_CMFS[spectra.CMFS_NAME].copy().align(colour.SpectralShape(360, 780, 5))
    illuminant = colour.SDS_ILLUMINANTS["D65"].copy().align(cmfs.shape)
    return cmfs, illuminant


def _single_colour_fn(method: str) -> Callable[[np.ndarray, object], tuple[np.ndarray, object]]:
    """``fn(rgb, state) -> (reflectance on LUT_WAVELENGTHS_NM, state)`` for one linear-sRGB colour.

    ``state`` carries a warm start between neighbouring colours (Jakob 2019's coefficients).
    """
    import colour
    from colour import recovery

    cmfs, illuminant = _colour_setup()
    grid = LUT_WAVELENGTHS_NM

    def resample(sd: object) -> np.ndarray:
        return np.interp(grid, sd.wavelengths, sd.values)

    d65_xy = colour.RGB_COLOURSPACES["sRGB"].whitepoint

    def xyz(rgb: np.ndarray) -> np.ndarray:
        return colour.RGB_to_XYZ(rgb, "sRGB")

    if method == SMITS1999:
        def fn(rgb, state):
            # Smits' RGB has sRGB primaries and white E: adapt the D65 white onto it (Bradford).
            rgb_smits = colour.XYZ_to_RGB(xyz(rgb), recovery.smits1999.RGB_COLOURSPACE_SMITS1999,
                                          illuminant=d65_xy, chromatic_adaptation_transform="Bradford")
            return resample(recovery.RGB_to_sd_Smits1999(np.clip(rgb_smits, 0.0, None))), state
    elif method == OTSU2018:
        def fn(rgb, state):
            return resample(recovery.XYZ_to_sd_Otsu2018(xyz(rgb), cmfs, illuminant)), state
    elif method == JAKOB2019:
        def fn(rgb, state):
            start = np.zeros(3) if state is None else state
            coeffs, _ = recovery.find_coefficients_Jakob2019(xyz(rgb), cmfs, illuminant,
                                                             coefficients_0=start)
            sd = recovery.sd_Jakob2019(coeffs, colour.SpectralShape(380, 780, 5))
            return resample(sd), coeffs
    else:
        raise SpecGenError(f"no tabulated uplifting for method {method!r}; known: {', '.join(METHODS)}")
    return fn


def _face_colour(face: int, a: float, b: float) -> np.ndarray:
    """Chroma with channel ``face`` = CHROMA_MAX and the other two (in index order) = a·max, b·max."""
    others = [c for c in range(3) if c != face]
    rgb = np.empty(3)
    rgb[face] = CHROMA_MAX
    rgb[others[0]] = a * CHROMA_MAX
    rgb[others[1]] = b * CHROMA_MAX
    return rgb


def build_face_table(method: str, n: int, progress: Callable[[float], None] | None = None) -> np.ndarray:
    """Tabulate ``method`` on the chroma cube's faces: reflectances (3, n, n, len(LUT_WAVELENGTHS_NM))."""
    import colour

    fn = _single_colour_fn(method)
    out = np.empty((3, n, n, LUT_WAVELENGTHS_NM.size))
    levels = np.linspace(0.0, 1.0, n)
    done, total = 0, 3 * n * n
    for face in range(3):
        state = None
        for i, a in enumerate(levels):
            # Serpentine order so each colour starts from its neighbour's solution (Jakob 2019).
            js = range(n) if i % 2 == 0 else range(n - 1, -1, -1)
            for j in js:
                with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
                    out[face, i, j], state = fn(_face_colour(face, a, levels[j]), state)
                done += 1
            if progress is not None:
                progress(done / total)
    return out


@functools.lru_cache(maxsize=8)
def face_table(method: str, n: int | None = None) -> np.ndarray:
    """Cached :func:`build_face_table` (memory, then ``.npz`` under the cache root)."""
    n = LUT_SIZE[method] if n is None else n
    path = cache_root() / f"uplift_{method}_{n}.npz"
    if path.is_file():
        with np.load(path) as data:
            if np.array_equal(data["wavelengths"], LUT_WAVELENGTHS_NM) and data["table"].shape[1] == n:
                return data["table"]
    table = build_face_table(method, n)

    with atomic_write(path, overwrite=True) as tmp:
        np.savez(tmp, table=table, wavelengths=LUT_WAVELENGTHS_NM)
    return table


def _lookup(table: np.ndarray, chroma: np.ndarray) -> np.ndarray:
    """Bilinear lookup of face tables at chroma (N, 3) whose largest component is CHROMA_MAX."""
    n = table.shape[1]
    face = np.argmax(chroma, axis=1)
    others = np.array([[1, 2], [0, 2], [0, 1]])[face]
    rows = np.arange(chroma.shape[0])
    ab = np.stack([chroma[rows, others[:, 0]], chroma[rows, others[:, 1]]], axis=1) / CHROMA_MAX
    x = np.clip(ab, 0.0, 1.0) * (n - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    f = x - i0
    fa, fb = f[:, :1], f[:, 1:]
    ia, ib = i0[:, 0], i0[:, 1]
    return ((1 - fa) * (1 - fb) * table[face, ia, ib] + (1 - fa) * fb * table[face, ia, ib + 1]
            + fa * (1 - fb) * table[face, ia + 1, ib] + fa * fb * table[face, ia + 1, ib + 1])


def _resample(values: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Spectra on LUT_WAVELENGTHS_NM (…, K) → ``wavelengths_nm`` (linear, ends held)."""
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    idx = np.clip(np.searchsorted(LUT_WAVELENGTHS_NM, w) - 1, 0, LUT_WAVELENGTHS_NM.size - 2)
    x0, x1 = LUT_WAVELENGTHS_NM[idx], LUT_WAVELENGTHS_NM[idx + 1]
    t = np.clip((w - x0) / (x1 - x0), 0.0, 1.0)
    return values[..., idx] * (1 - t) + values[..., idx + 1] * t


@functools.lru_cache(maxsize=16)
def _mallett_basis(key: tuple[float, ...]) -> np.ndarray:
    import colour

    basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    w = np.asarray(key)
    return np.stack([np.interp(w, basis.wavelengths, basis.values[:, c]) for c in range(3)])


def uplift_reflectance(rgb: np.ndarray, method: str, wavelengths_nm: np.ndarray,
                       lut_size: int | None = None) -> np.ndarray:
    """Reflectance-like spectra (…, Λ) of linear-sRGB colours ``rgb`` (…, 3) by ``method``.

    Colours are taken as ``s · c`` with ``c`` of largest component 0.5 (see module docstring), so
    the result scales linearly with the colour's brightness for every method. ``lut_size``
    overrides the face-grid size of tabulated methods (default :data:`LUT_SIZE`).
    """
    if method not in METHODS:
        raise SpecGenError(f"unknown uplifting method {method!r}; known: {', '.join(METHODS)}")
    rgb = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, None)
    shape = rgb.shape[:-1]
    flat = rgb.reshape(-1, 3)
    w = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
    if method == MALLETT2019:
        return (flat @ _mallett_basis(tuple(float(x) for x in w))).reshape(*shape, w.size)
    out = np.zeros((flat.shape[0], w.size))
    scale = 2.0 * flat.max(axis=1)
    lit = scale > 0
    if np.any(lit):
        chroma = flat[lit] / scale[lit, None]
        out[lit] = scale[lit, None] * _resample(_lookup(face_table(method, lut_size), chroma), w)
    return out.reshape(*shape, w.size)


def uplift_albedo(rgb: np.ndarray, method: str, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Reflectance spectra (N, Λ) of a few linear-sRGB albedos ``rgb`` (N, 3), each uplifted exactly.

    For the colours of a fitted BRDF (:mod:`.photo_fit`), not for images: every colour is a call
    to colour-science (no face table). As PBRT 4e's ``RGBAlbedoSpectrum``, a colour whose largest
    component is ≤ 1 is uplifted as it is; a brighter one (a fit that broke energy conservation)
    is uplifted at maximum 1 and scaled back. Black stays black.
    """
    if method not in METHODS:
        raise SpecGenError(f"unknown uplifting method {method!r}; known: {', '.join(METHODS)}")
    rgb = np.clip(np.atleast_2d(np.asarray(rgb, dtype=np.float64)), 0.0, None)
    w = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
    scale = np.maximum(rgb.max(axis=1), 1.0)
    if method == MALLETT2019:
        return rgb @ _mallett_basis(tuple(float(x) for x in w))
    import colour

    fn = _single_colour_fn(method)
    out = np.zeros((rgb.shape[0], w.size))
    for i, (c, s) in enumerate(zip(rgb, scale)):
        if c.max() > 0:
            with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
                out[i] = s * _resample(fn(c / s, None)[0], w)
    return out


def uplift_radiance_image(rgb: np.ndarray, method: str, wavelengths_nm: np.ndarray,
                          white: str = spectra.DEFAULT_ILLUMINANT, lut_size: int | None = None) -> np.ndarray:
    """Spectral radiance image (H, W, Λ) estimated from a linear-sRGB render (H, W, 3).

    ``L(λ) = ρ̂(λ) · S_white(λ)``, so a pixel equal to the white's RGB returns the white's spectrum.
    """
    rho = uplift_reflectance(rgb, method, wavelengths_nm, lut_size)
    return rho * spectra.illuminant_spd(white, np.atleast_1d(wavelengths_nm))
