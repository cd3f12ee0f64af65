"""The diffuse body's spectral shape: a natural reflectance of the photo's body colour.

A photo fixes three numbers of the body's spectrum (its colour); the other degrees of freedom come
from a prior. Measured on the validation split, the network's body spectra are a weak prior there
(spectral PSNR of the body shape, after a tint matched to the colour: 23 dB), while a natural
reflectance of the same colour — Otsu et al.'s (2018) clustered basis of measured reflectances,
:mod:`specgen_addon.spectral_recovery` — is a strong one (34 dB; docs/refinement.md). So the
refinement keeps the network's colour and lobe, and takes the body's *shape* from that basis.

That holds for a diffuse body under an interface (plastics, paints, coated materials). A metal has
no separate body: its near-Lambertian part is the tail of the same Fresnel-coloured reflection as
its lobe, and the network's own metal spectra are the better prior. :func:`has_separate_body`
tells the two apart from the network's table.
"""

from __future__ import annotations

import numpy as np

from ..errors import SpecGenError
from ..spectral_recovery import otsu2018_reflectance, xyz_of_reflectance

#: Body priors of :class:`~specgen_addon.refine.RefineOptions`: Otsu 2018 (default) or the network's.
BODY_PRIORS = ("otsu2018", "network")
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
        return otsu2018_reflectance(xyz, wavelengths_nm) / np.pi
    except SpecGenError:
        return None
