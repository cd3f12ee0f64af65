"""Metallic car paint: a coloured pigment base, metallic flakes, a clear coat.

The effective-BRDF structure of Günther, Chen, Goesele, Wald & Seidel 2005 ("Efficient
acquisition and realistic rendering of car paint", VMV): a diffuse pigment term, a broad glossy
flake lobe and a sharp clear-coat lobe, here with physical ingredients:

* pigment: Lambertian ``ρ(λ)`` from a measured (or Otsu 2018) reflectance spectrum;
* flakes: a fraction ``coverage`` of the base area is metal flakes, modelled as a GGX lobe of
  roughness ``α_f`` (the spread of flake orientations) with the conductor Fresnel of a measured
  ``(η, k)(λ)`` (aluminium flakes are the common case; the metal is split like every metal);
* clear coat: GGX dielectric interface attenuating the base by ``(1 − E_c(μi)) (1 − E_c(μo))``.

``f = f_coat + (1 − E_c(μi))(1 − E_c(μo)) [c f_flake + (1 − c) ρ/π]``: reciprocal; the base
albedo is ``c E_flake + (1 − c) ρ ≤ 1`` because a GGX conductor lobe's albedo is ≤ 1.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from specgen_addon.corpus.fresnel import fresnel_dielectric
from specgen_addon.corpus.material import COS_NODES, ClearCoat, Conductor, Reflectance, _lerp_nodes
from specgen_addon.corpus.microfacet import lookup_mu, specular_albedo_curves, specular_geometry
from specgen_addon.corpus.families.base import FamilyMaterial, check_alpha, register


@register
@dataclass(frozen=True)
class CarPaint(FamilyMaterial):
    """Pigment ``base_color``, flakes (``flake_metal``, ``flake_alpha``, ``coverage``), ``coat``."""

    base_color: Reflectance | None = None
    flake_metal: Conductor = Conductor("Al")
    flake_alpha: float = 0.3
    coverage: float = 0.3
    coat: ClearCoat = ClearCoat(0.03, 1.5)
    family: ClassVar[str] = "car_paint"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_alpha(self.name, self.flake_alpha, self.coat.alpha)
        if self.base_color is None:
            raise ValueError("car paint needs a base colour spectrum")
        if not 0.0 <= self.coverage <= 1.0:
            raise ValueError(f"flake coverage {self.coverage} outside [0, 1]")

    @property
    def kind(self) -> str:
        return f"car_paint/{self.flake_metal.metal}"

    def _spectral(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        flake_f, rho, coat_f, coat_e = _tables(self, tuple(float(x) for x in w))
        f = _lerp_nodes(flake_f, cos_d) * (self.coverage * specular_geometry(cos_i, cos_o, cos_h,
                                                                             self.flake_alpha))[:, None]
        f += (1.0 - self.coverage) * rho / np.pi
        f *= (1.0 - lookup_mu(coat_e, cos_i)) * (1.0 - lookup_mu(coat_e, cos_o))
        f += (specular_geometry(cos_i, cos_o, cos_h, self.coat.alpha) * _lerp_nodes(coat_f, cos_d))[:, None]
        return f


@functools.lru_cache(maxsize=4096)
def _tables(m: CarPaint, w: tuple[float, ...]):
    wa = np.asarray(w)
    flake_f = np.ascontiguousarray(m.flake_metal.fresnel(COS_NODES, wa).T)
    coat_f = fresnel_dielectric(COS_NODES, m.coat.eta)
    coat_e = specular_albedo_curves(m.coat.alpha, np.array([m.coat.eta]))
    return flake_f, m.base_color.at(wa), coat_f, coat_e
