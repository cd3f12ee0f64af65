"""A material's colour twin: the same material with every spectrum replaced by what its colour alone gives.

SpecGen sees an RGB photo, and the test split holds out whole spectra (:mod:`.spectra_sources`),
so of a held-out reflectance a method can know its colour, not its spectrum (metamerism). The twin
keeps every parameter of the material (roughness, films, coats, lobe shapes, metals) and replaces
each reflectance ``ρ(λ)`` by the Otsu, Yamamoto & Hachisuka (2018) reflectance of its own CIE XYZ
under D65 (:func:`specgen_addon.spectral.rgb_to_spectrum.xyz_to_spectrum`, ``"Otsu 2018"``): the same colour, a smooth spectrum.

Rendering the twin against the material (``bench/colour_ceiling.py``) measures how much spectral
PSNR a method loses that gets every colour right and guesses spectra as Otsu 2018 does. It is a
reference, not a bound: an estimator that learned the corpus's own spectra could do better on some
materials; and the held-out metals (Cu, Ni) are kept exact, which no RGB method can know, so the twin
is optimistic for them.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import numpy as np

from specgen_addon.spectral.otsu2018 import xyz_of_reflectance
from specgen_addon.spectral.rgb_to_spectrum import xyz_to_spectrum
from specgen_addon.corpus.material import Reflectance
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM

#: Wavelengths (nm) the colours are integrated on: 5 nm over the CIE 1931 observer's range.
_XYZ_GRID_NM = np.arange(360.0, 831.0, 5.0)


#: Alternating projections that restore the colour Otsu 2018's clipping to [0, 1] changed.
_COLOUR_STEPS = 200


@functools.lru_cache(maxsize=1)
def _xyz_matrix() -> np.ndarray:
    """(N, 3): values on :data:`REFLECTANCE_GRID_NM` → CIE XYZ (D65), as :meth:`Reflectance.at` spreads them."""
    eye = np.eye(REFLECTANCE_GRID_NM.size)
    return np.stack([xyz_of_reflectance(np.interp(_XYZ_GRID_NM, REFLECTANCE_GRID_NM, e), _XYZ_GRID_NM)
                     for e in eye])


def reflectance_twin(reflectance: Reflectance) -> Reflectance:
    """The Otsu 2018 reflectance of ``reflectance``'s CIE XYZ (D65), on the corpus grid.

    Otsu 2018 clips its spectrum to [0, 1], which shifts a saturated colour by a few per cent; from
    there, alternating projections (onto the spectra of exactly that colour, then onto [0, 1]) find
    a spectrum in [0, 1] of the exact colour close to Otsu's, so the twin keeps the colour.
    """
    m = _xyz_matrix()
    xyz = np.asarray(reflectance.values, np.float64) @ m
    if xyz[1] <= 0.0:
        return reflectance                  # black: no colour to recover, and nothing to lose
    values = xyz_to_spectrum(xyz, REFLECTANCE_GRID_NM, method="Otsu 2018")
    gram = np.linalg.inv(m.T @ m)
    for _ in range(_COLOUR_STEPS):
        values = np.clip(values + m @ (gram @ (xyz - values @ m)), 0.0, 1.0)
    return Reflectance(f"twin of {reflectance.source}", tuple(round(float(v), 6) for v in values))


def replace_reflectances(material: object, replace: Callable[[Reflectance], Reflectance]) -> object:
    """``material`` (any corpus family, frozen dataclasses) with every reflectance ``ρ`` replaced by
    ``replace(ρ)``, in field order; every other parameter (metals included) kept."""
    if isinstance(material, Reflectance):
        return replace(material)
    if not dataclasses.is_dataclass(material) or isinstance(material, type):
        return material
    changes = {}
    for field in dataclasses.fields(material):
        if not field.init:
            continue
        value = getattr(material, field.name)
        new = replace_reflectances(value, replace)
        if new is not value:
            changes[field.name] = new
    return dataclasses.replace(material, **changes) if changes else material


def colour_twin(material: object) -> object:
    """``material`` (any corpus family, frozen dataclasses) with every reflectance replaced by its twin."""
    return replace_reflectances(material, reflectance_twin)
