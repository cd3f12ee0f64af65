"""Corpus material families beyond the classic plastic/metal recipe, one module each.

``classic`` (:class:`~..material.Material`), :class:`TintedCoat`, :class:`CarPaint`,
:class:`ThinFilm`, :class:`Sheen` and :class:`Lobes` (long-tailed, very sharp and retro-reflective
lobes) all follow the BRDF protocol; :func:`material_from_dict` rebuilds any of them.
"""

from specgen_addon.corpus.families.base import (FAMILIES, FamilyMaterial, check_family_names, directional_albedo, family_names,
                   halfvector_quadrature, hemisphere_quadrature, material_from_dict)
from specgen_addon.corpus.families.car_paint import CarPaint
from specgen_addon.corpus.families.lobes import Lobes
from specgen_addon.corpus.families.sheen import Sheen
from specgen_addon.corpus.families.thin_film import ThinFilm, airy_reflectance
from specgen_addon.corpus.families.tinted_coat import TintedCoat
from specgen_addon.corpus.families.catalogue import FAMILY_NAMES

__all__ = ["CarPaint", "FAMILIES", "FAMILY_NAMES", "FamilyMaterial", "Lobes", "Sheen", "ThinFilm",
           "TintedCoat", "airy_reflectance", "check_family_names", "directional_albedo", "family_names", "halfvector_quadrature",
           "hemisphere_quadrature", "material_from_dict"]
