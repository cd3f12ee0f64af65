"""The diffuse body's spectral shape: a natural reflectance of the photo's body colour.

A photo fixes three numbers of the body's spectrum (its colour); the other degrees of freedom come
from a prior. Measured on the validation split, the network's body spectra are a weak prior there
(spectral PSNR of the body shape, after a tint matched to the colour: 23 dB), while a natural
reflectance of the same colour — Otsu et al.'s (2018) clustered basis of measured reflectances,
:mod:`specgen_addon.spectral.otsu2018` — is a strong one (34 dB; docs/refinement.md). So the
refinement keeps the network's colour and lobe, and takes the body's *shape* from that basis.

That holds for a diffuse body under an interface (plastics, paints, coated materials). A metal has
no separate body: its near-Lambertian part is the tail of the same Fresnel-coloured reflection as
its lobe, and the network's own metal spectra are the better prior. :func:`has_separate_body`
tells the two apart from the network's table.

Two mixes of the priors are options, not defaults (:func:`blended_body`, :func:`blind_share`): on
fresh validation photos both lost to Otsu 2018's body alone (lab/notebook/refinement-priors.md).
"""

from __future__ import annotations

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral import spectra
from specgen_addon.spectral.otsu2018 import xyz_of_reflectance
from specgen_addon.spectral.rgb_to_spectrum import xyz_to_spectrum

#: Body priors of :class:`~specgen_addon.generate.refine.RefineOptions`: Otsu 2018 (default), the network's, or
#: a convex blend of the two (:func:`blended_body`), or Otsu 2018's where the eye sees and the network's in
#: the spectral tails it barely sees (:func:`blind_share`).
BODY_PRIORS = ("otsu2018", "network", "blend", "tails")
#: θh rows (MERL index, < 3°) and θd columns (< 40°) where the lobe's colour is read.
_PEAK_THETA_H, _PEAK_THETA_D = 12, 40
#: Lobe/body spectral-shape distance (std of the log ratio over 420–680 nm) below which the lobe
#: has the body's colour, as a metal's does (validation metals 0.02–0.10, plastics 0.31–0.81).
METAL_SHAPE_DISTANCE = 0.15


def has_separate_body(values: np.ndarray, floor: np.ndarray, wavelengths_nm: np.ndarray) -> bool:
    """Whether the table's diffuse floor is a body of its own (not a metal's reflection tail).

    ``values`` is the table (90, 90, 180, Λ) in sr⁻¹, ``floor`` its diffuse floor (Λ,). A table
    whose specular peak outshines its floor and has the floor's spectral shape is a conductor.
    """
    lobe = (values[:_PEAK_THETA_H, :_PEAK_THETA_D] - floor).reshape(-1, floor.size).mean(axis=0)
    if lobe.mean() < floor.mean():          # no lobe to speak of: a rough, body-dominated table
        return True
    band = (wavelengths_nm >= 420.0) & (wavelengths_nm <= 680.0)
    if band.sum() < 3:
        band = np.ones_like(wavelengths_nm, dtype=bool)
    ratio = np.log(np.clip(lobe[band], 1e-9, None) / np.clip(floor[band], 1e-9, None))
    return float(np.std(ratio)) >= METAL_SHAPE_DISTANCE


def natural_body(body: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray | None:
    """The Otsu 2018 body (sr⁻¹, same shape) with the colour of the Lambertian ``body`` (sr⁻¹),
    or None where it has no colour to recover (black, or a grid outside the visible range)."""
    reflectance = np.clip(np.asarray(body, np.float64) * np.pi, 0.0, None)
    try:
        xyz = xyz_of_reflectance(reflectance, wavelengths_nm)
        if xyz[1] < 1e-4:
            return None
        return xyz_to_spectrum(xyz, wavelengths_nm, method="Otsu 2018") / np.pi
    except SpecGenError:
        return None


def blended_body(natural: np.ndarray, network: np.ndarray, network_share) -> np.ndarray:
    """``(1 − w)·natural + w·network`` (sr⁻¹): two bodies of the photo's colour, mixed (``w`` a
    number, or one per band).

    Both match the photo's body colour, and colour is linear in the spectrum, so any convex mix
    matches it too; its spectral squared error is at most the same mix of the two errors. A hedge
    where either prior can be a metamer of the material's body (docs/refinement.md).
    """
    if not np.all((np.asarray(network_share) >= 0.0) & (np.asarray(network_share) <= 1.0)):
        raise SpecGenError(f"the network's share of the body must be in [0, 1], got {network_share!r}")
    return (1.0 - network_share) * np.asarray(natural, np.float64) + network_share * np.asarray(network, np.float64)


def visibility(wavelengths_nm: np.ndarray) -> np.ndarray:
    """How well a colour measurement sees each band: the largest of the CIE 1931 x̄, ȳ, z̄ there,
    each divided by its own peak (1 at a peak, → 0 in the far violet and far red), (Λ,)."""
    w = np.asarray(wavelengths_nm, np.float64)
    peaks = spectra.cmfs(np.arange(360.0, 831.0)).max(axis=0)
    return (spectra.cmfs(w) / peaks).max(axis=1)


def blind_share(wavelengths_nm: np.ndarray, threshold: float) -> np.ndarray:
    """Per band, the share of the body left to the network's prior: ``clip(1 − v/threshold, 0, 1)``
    with ``v`` the :func:`visibility`. A photo fixes the body's colour, which says almost nothing
    about bands the eye barely sees (≲ 410 nm, ≳ 680 nm), where Otsu 2018's basis extrapolates."""
    if not 0.0 < threshold <= 1.0:
        raise SpecGenError(f"the visibility threshold must be in (0, 1], got {threshold!r}")
    return np.clip(1.0 - visibility(wavelengths_nm) / threshold, 0.0, 1.0)
