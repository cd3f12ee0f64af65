"""Diffuse reflectance spectra for the corpus, and the honest train / val / test split of them.

Measured spectra come from the sets colour-science ships: the ColorChecker charts
(``colour.characterisation.SDS_COLOURCHECKERS``: BabelColor Average, ColorChecker N Ohta,
ISO 17321-1, PMC), the CIE test colour samples (``colour.quality.SDS_TCS``, CIE 13.3) and the NIST
CQS 7.4 / 9.0 samples (``colour.quality.SDS_VS``, Davis & Ohno 2010). New spectra are drawn with
Otsu et al. 2018's clustered PCA basis (``colour.recovery.XYZ_to_sd_Otsu2018``) from a random
colour. All spectra are resampled to :data:`REFLECTANCE_GRID_NM` (colour's Sprague interpolation,
constant extrapolation) and clipped to [0, 1].

Splitting is done by *source*, not by material: the same ColorChecker patch measured by two
labs, or two charts printing the same pigment, are near-identical spectra. Spectra are therefore
joined into groups (same ColorChecker patch name, or RMS difference below
:data:`DUPLICATE_RMS`, transitively), and each group goes to one split, chosen by a stable hash of
its name. Metals are split by element (:data:`METAL_SPLITS`).
"""

from __future__ import annotations

import functools
import zlib
from dataclasses import dataclass

import numpy as np

from specgen_addon.common.errors import SpecGenError

SPLITS: tuple[str, ...] = ("train", "val", "test")
#: Percent of source groups per split (hash buckets 0–99): test < 20 ≤ val < 30 ≤ train.
_SPLIT_BUCKETS = (("test", 20), ("val", 30), ("train", 100))

#: Wavelengths (nm) on which reflectance spectra are stored in materials and manifests.
REFLECTANCE_GRID_NM = np.arange(380.0, 781.0, 5.0)
#: Two spectra closer than this RMS difference (reflectance units) count as the same source.
DUPLICATE_RMS = 0.03

COLOURCHECKER_SETS: tuple[str, ...] = ("BabelColor Average", "ColorChecker N Ohta",
                                       "ISO 17321-1", "PMC")
#: Charts whose patch names denote the same physical ColorChecker patches.
_SAME_PATCHES = frozenset({"BabelColor Average", "ColorChecker N Ohta", "ISO 17321-1"})
VS_SETS: tuple[str, ...] = ("NIST CQS 7.4", "NIST CQS 9.0")

#: Conductors per split: no metal's (η, k) table is shared between splits.
METAL_SPLITS: dict[str, tuple[str, ...]] = {
    "train": ("Ag", "Al", "Au", "Cr", "Mo", "Rh", "W"),
    "val": ("Ir",),
    "test": ("Cu", "Ni"),
}


@dataclass(frozen=True)
class MeasuredSpectrum:
    """One measured reflectance: ``id`` is ``"<set>/<sample>"``; ``group`` names its source group."""

    id: str
    group: str
    split: str
    values: np.ndarray  # on REFLECTANCE_GRID_NM, in [0, 1]


def resample_sd(sd) -> np.ndarray:
    """A colour ``SpectralDistribution`` on :data:`REFLECTANCE_GRID_NM`, clipped to [0, 1]."""
    import colour

    step = float(REFLECTANCE_GRID_NM[1] - REFLECTANCE_GRID_NM[0])
    shape = colour.SpectralShape(REFLECTANCE_GRID_NM[0], REFLECTANCE_GRID_NM[-1], step)
    aligned = sd.copy().align(shape, extrapolator_kwargs={"method": "Constant",
                                                          "left": None, "right": None})
    return np.clip(np.asarray(aligned.values, dtype=np.float64), 0.0, 1.0)


def rms_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """RMS difference over wavelengths between spectra ``a`` (..., K) and ``b`` (M, K) -> (..., M)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return np.sqrt(np.mean((a[..., None, :] - b) ** 2, axis=-1))


def split_of_key(key: str) -> str:
    """Deterministic split of a source group (CRC-32 of its name, stable across runs/platforms)."""
    bucket = zlib.crc32(key.encode("utf-8")) % 100
    return next(split for split, limit in _SPLIT_BUCKETS if bucket < limit)


def _raw_measured() -> list[tuple[str, np.ndarray]]:
    from colour.characterisation import SDS_COLOURCHECKERS
    from colour.quality import SDS_TCS, SDS_VS

    out = [(f"{chart}/{name}", resample_sd(sd))
           for chart in COLOURCHECKER_SETS for name, sd in SDS_COLOURCHECKERS[chart].items()]
    out += [(f"CIE TCS/{name}", resample_sd(sd)) for name, sd in SDS_TCS.items()]
    out += [(f"{vs}/{name}", resample_sd(sd)) for vs in VS_SETS for name, sd in SDS_VS[vs].items()]
    return out


@functools.lru_cache(maxsize=1)
def measured_spectra() -> tuple[MeasuredSpectrum, ...]:
    """All measured spectra with their source group and split (groups never straddle splits)."""
    raw = _raw_measured()
    ids = [i for i, _ in raw]
    values = np.stack([v for _, v in raw])
    parent = list(range(len(raw)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    dist = rms_distance(values, values)
    for i in range(len(raw)):
        chart_i, patch_i = ids[i].split("/", 1)
        for j in range(i):
            chart_j, patch_j = ids[j].split("/", 1)
            same_patch = patch_i == patch_j and {chart_i, chart_j} <= _SAME_PATCHES
            if same_patch or dist[i, j] < DUPLICATE_RMS:
                parent[root(i)] = root(j)
    members: dict[int, list[int]] = {}
    for i in range(len(raw)):
        members.setdefault(root(i), []).append(i)
    out = []
    for idx in members.values():
        group = min(ids[i] for i in idx)
        split = split_of_key(group)
        out += [MeasuredSpectrum(ids[i], group, split, values[i]) for i in idx]
    out.sort(key=lambda s: s.id)
    for s in out:
        s.values.setflags(write=False)
    return tuple(out)


def measured_groups(split: str) -> list[list[MeasuredSpectrum]]:
    """The measured source groups of ``split``, each a list of its member spectra, in name order."""
    if split not in SPLITS:
        raise SpecGenError(f"unknown split {split!r}; expected one of {', '.join(SPLITS)}")
    groups: dict[str, list[MeasuredSpectrum]] = {}
    for s in measured_spectra():
        if s.split == split:
            groups.setdefault(s.group, []).append(s)
    return [groups[k] for k in sorted(groups)]


def draw_otsu2018(rng: np.random.Generator) -> np.ndarray:
    """A new smooth reflectance from Otsu et al. 2018's basis for a random in-gamut sRGB colour.

    The colour is uniform in encoded sRGB on [0.03, 0.97]³ (linear albedo ~0.002–0.93), converted
    to XYZ under D65 and recovered with ``colour.recovery.XYZ_to_sd_Otsu2018``; clipped to [0, 1].
    """
    import colour

    encoded = rng.uniform(0.03, 0.97, size=3)
    xyz = colour.RGB_to_XYZ(colour.cctf_decoding(encoded, function="sRGB"),
                            colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    sd = colour.recovery.XYZ_to_sd_Otsu2018(xyz)
    return resample_sd(sd)
