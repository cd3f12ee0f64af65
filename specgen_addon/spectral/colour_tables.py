"""The colour-science tables SpecGen needs, precomputed into ``data/colour_tables.npz``.

A stock Blender has numpy but not colour-science, so everything colorimetric the add-on uses at run
time is read from one small file generated *from* colour-science (``python
scripts/make_colour_tables.py``): colour-science stays the single source, and a test regenerates
the file and compares it with the shipped one. The tables are stored at their native sampling
(interpolation happens in :mod:`specgen_addon.spectral.spectra`, exactly as it did on colour's own data):

* ``cmfs_*``: CIE 1931 2° standard observer (``colour.MSDS_CMFS``), 360–830 nm;
* ``illuminant_*``: every CIE illuminant of ``colour.SDS_ILLUMINANTS`` (ragged, with offsets);
* ``mallett2019_*``: the sRGB basis reflectances of Mallett & Yuksel (2019)
  (``colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019``);
* ``otsu2018_*``: Otsu, Yamamoto & Hachisuka's (2018) clustered reflectance basis
  (``colour.recovery.BASIS_FUNCTIONS_OTSU2018``, ``CLUSTER_MEANS_OTSU2018``,
  ``SELECTOR_ARRAY_OTSU2018`` on ``SPECTRAL_SHAPE_OTSU2018``), read by :mod:`.otsu2018`;
* ``srgb_*``: the sRGB colourspace's XYZ ↔ RGB matrices and white point (XYZ);
* ``bradford``: the Bradford chromatic adaptation matrix (``CAT_BRADFORD``).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import SpecGenError

TABLES_PATH = Path(__file__).resolve().parent / "data" / "colour_tables.npz"
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"


def build_tables() -> dict[str, np.ndarray]:
    """Compute every table from colour-science (build time only: needs ``colour``)."""
    import colour

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    names = sorted(colour.SDS_ILLUMINANTS)
    sds = [colour.SDS_ILLUMINANTS[n] for n in names]
    offsets = np.cumsum([0] + [sd.wavelengths.size for sd in sds])
    basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    otsu = colour.recovery
    return {
        "cmfs_wavelengths_nm": np.asarray(cmfs.wavelengths, np.float64),
        "cmfs_values": np.asarray(cmfs.values, np.float64),
        "illuminant_names": np.asarray(names),
        "illuminant_offsets": np.asarray(offsets, np.int64),
        "illuminant_wavelengths_nm": np.concatenate([sd.wavelengths for sd in sds]).astype(np.float64),
        "illuminant_values": np.concatenate([sd.values for sd in sds]).astype(np.float64),
        "mallett2019_wavelengths_nm": np.asarray(basis.wavelengths, np.float64),
        "mallett2019_values": np.asarray(basis.values, np.float64),
        "otsu2018_wavelengths_nm": np.asarray(otsu.SPECTRAL_SHAPE_OTSU2018.wavelengths, np.float64),
        "otsu2018_basis": np.asarray(otsu.BASIS_FUNCTIONS_OTSU2018, np.float64),
        "otsu2018_means": np.asarray(otsu.CLUSTER_MEANS_OTSU2018, np.float64),
        "otsu2018_selector": np.asarray(otsu.SELECTOR_ARRAY_OTSU2018, np.float64),
        "srgb_xyz_to_rgb": np.asarray(srgb.matrix_XYZ_to_RGB, np.float64),
        "srgb_rgb_to_xyz": np.asarray(srgb.matrix_RGB_to_XYZ, np.float64),
        "srgb_white_xyz": np.asarray(colour.xy_to_XYZ(srgb.whitepoint), np.float64),
        "bradford": np.asarray(colour.adaptation.CAT_BRADFORD, np.float64),
    }


def write_tables(path: str | Path = TABLES_PATH) -> Path:
    """Regenerate the shipped file from colour-science."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **build_tables())
    return path


@functools.lru_cache(maxsize=1)
def tables() -> dict[str, np.ndarray]:
    """The shipped tables (read once; treat as read-only)."""
    try:
        with np.load(TABLES_PATH, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except OSError as exc:
        raise SpecGenError(f"{TABLES_PATH}: colour tables missing or unreadable "
                           "(run scripts/make_colour_tables.py)") from exc


def mallett2019_basis(wavelengths_nm: np.ndarray) -> np.ndarray:
    """(Λ, 3) Mallett & Yuksel's (2019) basis reflectances, red, green, blue (the sRGB primaries'
    uplifts; they sum to 1), at ``wavelengths_nm`` (nm); the nearest value is held outside 380–780 nm."""
    t = tables()
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    return np.stack([np.interp(w, t["mallett2019_wavelengths_nm"], t["mallett2019_values"][:, c])
                     for c in range(3)], axis=1)


def illuminant(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths nm, relative SPD) of the CIE illuminant ``name`` as colour-science tabulates it."""
    kelvin = blackbody_temperature(name)
    if kelvin is not None:
        return blackbody(kelvin)
    rgb = rgb_colour(name)
    if rgb is not None:
        return rgb_illuminant(rgb)
    t = tables()
    names = [str(n) for n in t["illuminant_names"]]
    if name not in names:
        raise SpecGenError(f"unknown illuminant {name!r}; known: {', '.join(names[:12])}, ...")
    i = names.index(name)
    lo, hi = t["illuminant_offsets"][i], t["illuminant_offsets"][i + 1]
    return t["illuminant_wavelengths_nm"][lo:hi], t["illuminant_values"][lo:hi]


def blackbody_temperature(name: str) -> float | None:
    """The colour temperature (K) a name like ``"3200K"`` gives, None for any other name; a
    temperature outside 1000–40000 K is refused."""
    text = str(name).strip()
    if not text.upper().endswith("K"):
        return None
    try:
        kelvin = float(text[:-1])
    except ValueError:
        return None
    if not 1000.0 <= kelvin <= 40000.0:
        raise SpecGenError(f"colour temperature {text} lies outside 1000–40000 K")
    return kelvin


def rgb_colour(name: str) -> tuple[float, float, float] | None:
    """The linear-sRGB colour a name like ``"1/0.8/0.6"`` gives, None for any other name; negative,
    non-finite or all-zero values are refused."""
    parts = str(name).strip().split("/")
    if len(parts) != 3:
        return None
    try:
        rgb = tuple(float(p) for p in parts)
    except ValueError:
        return None
    if not all(np.isfinite(rgb)) or min(rgb) < 0 or max(rgb) <= 0:
        raise SpecGenError(f"an RGB colour needs three non-negative numbers, not all zero, got {name!r}")
    return rgb  # type: ignore[return-value]


def rgb_illuminant(rgb: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths nm, relative SPD) of a light of linear-sRGB colour ``rgb``: D65 filtered by
    Mallett & Yuksel's (2019) reflectance of ``rgb / max(rgb)``, so that the light, seen by a
    camera balanced to D65, has the colour ``rgb`` (the basis spans the sRGB gamut exactly);
    380–780 nm, the basis' support."""
    t = tables()
    wl = t["mallett2019_wavelengths_nm"]
    d65_wl, d65 = illuminant("D65")
    c = np.asarray(rgb, np.float64) / max(rgb)
    return wl.copy(), np.interp(wl, d65_wl, d65) * (mallett2019_basis(wl) @ c)


def blackbody(kelvin: float) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths nm, relative SPD) of a black body at ``kelvin`` (Planck's law, 360–830 nm, 1 nm;
    the same curve as ``colour.sd_blackbody``), scaled to 1 at 560 nm."""
    wl = np.arange(360.0, 831.0, 1.0)
    c1, c2 = 3.741771852e-16, 1.438776877e-2          # 2πhc² (W·m²), hc/k (m·K)
    lam = wl * 1e-9
    spd = c1 / lam ** 5 / np.expm1(c2 / (lam * kelvin))
    return wl, spd / spd[200]


def von_kries_bradford(xyz_source_white: np.ndarray, xyz_target_white: np.ndarray) -> np.ndarray:
    """Von Kries adaptation matrix in the Bradford cone space (as
    ``colour.adaptation.matrix_chromatic_adaptation_VonKries(..., transform="Bradford")``)."""
    m = tables()["bradford"]
    lms_s = m @ np.asarray(xyz_source_white, np.float64)
    lms_t = m @ np.asarray(xyz_target_white, np.float64)
    return np.linalg.inv(m) @ np.diag(lms_t / lms_s) @ m
