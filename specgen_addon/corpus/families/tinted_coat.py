"""Tinted (absorbing) dielectric coat over a plastic or metal base: dyed lacquers, coloured vinyl
and foil films, tinted anodised metals. The highlight of the base is coloured by the coat.

Layers, from the top (Weidlich & Wilkie 2007, "Arbitrarily layered micro-facet surfaces", with
their no-refraction-offset simplification):

* a GGX dielectric interface of index ``η_c`` (white highlight), which transmits
  ``(1 − E_c(μi)) (1 − E_c(μo))`` as in :class:`~..material.Material`'s clear coat;
* an absorbing layer following Beer–Lambert: along a path at angle ``θt`` inside the coat
  (Snell: ``cos θt = √(1 − (1 − μ²)/η_c²)``) the transmittance is ``exp(−A(λ)/cos θt)``, with
  the normal-incidence absorbance ``A(λ) = −density · ln τ(λ)`` taken from a measured spectrum
  ``τ(λ)`` (so the dye's hue is a real reflectance's, split with it). Light crosses the layer
  twice: ``T = exp(−A (1/cos θt,i + 1/cos θt,o))``, symmetric in i, o;
* the base: a plastic or metal :class:`~..material.Material` without coat.

``f = f_coat + (1 − E_c(μi)) (1 − E_c(μo)) T(μi, μo, λ) f_base``: reciprocal, and since
``T ≤ 1`` the albedo stays below the clear-coated base's (≤ 1).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from specgen_addon.corpus.fresnel import fresnel_dielectric
from specgen_addon.corpus.material import COS_NODES, ClearCoat, Material, Reflectance, _lerp_nodes, _lookup
from specgen_addon.corpus.microfacet import lookup_mu, specular_albedo_curves, specular_geometry
from specgen_addon.corpus.families.base import FamilyMaterial, register

#: Smallest transmittance a dye spectrum is clipped to before taking its logarithm.
TAU_FLOOR = 1e-3


@register
@dataclass(frozen=True)
class TintedCoat(FamilyMaterial):
    """An absorbing coat (``tint`` spectrum, ``density``) with a GGX top interface over ``base``."""

    base: Material | None = None
    coat: ClearCoat = ClearCoat(0.05, 1.5)
    tint: Reflectance | None = None
    density: float = 0.5
    family: ClassVar[str] = "tinted_coat"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.base is None or self.tint is None:
            raise ValueError("a tinted coat needs a base material and a tint spectrum")
        if self.base.coat is not None:
            raise ValueError("the base of a tinted coat has no coat of its own")
        if not 0.0 <= self.density <= 5.0:
            raise ValueError(f"density {self.density} outside [0, 5]")

    @property
    def kind(self) -> str:
        return f"tinted_coat/{self.base.kind}"

    def absorbance(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """Normal-incidence absorbance ``A(λ) = −density · ln τ(λ)`` of the coat (one crossing)."""
        return -self.density * np.log(np.maximum(self.tint.at(wavelengths_nm), TAU_FLOOR))

    def _spectral(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        wt = tuple(float(x) for x in w)
        f = self.base._chunk(_lookup(self.base, wt), cos_i, cos_o, cos_h, cos_d)
        coat_f, coat_e, absorb = _coat_tables(self, wt)
        eta2 = self.coat.eta ** 2
        path = (1.0 / np.sqrt(1.0 - (1.0 - cos_i ** 2) / eta2) + 1.0 / np.sqrt(1.0 - (1.0 - cos_o ** 2) / eta2))
        f *= np.exp(-path[:, None] * absorb[None, :])
        f *= ((1.0 - lookup_mu(coat_e, cos_i)) * (1.0 - lookup_mu(coat_e, cos_o)))
        f += (specular_geometry(cos_i, cos_o, cos_h, self.coat.alpha) * _lerp_nodes(coat_f, cos_d))[:, None]
        return f


@functools.lru_cache(maxsize=4096)
def _coat_tables(m: TintedCoat, w: tuple[float, ...]):
    coat_f = fresnel_dielectric(COS_NODES, m.coat.eta)
    coat_e = specular_albedo_curves(m.coat.alpha, np.array([m.coat.eta]))
    return coat_f, coat_e, m.absorbance(np.asarray(w))
