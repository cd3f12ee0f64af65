"""Lobe shapes beyond middling GGX: long-tailed (GTR), very sharp, and retro-reflective lobes,
on a dispersive dielectric over a diffuse base.

* Long tails: the Generalized-Trowbridge-Reitz distribution of Burley 2012 ("Physically-Based
  Shading at Disney", SIGGRAPH course, Appendix B), normalised so ``∫ D cos θh dωh = 1``:
  ``D = (γ − 1)(α² − 1) / (π (1 − (α²)^{1−γ})) · (1 + (α² − 1) cos²θh)^{−γ}``, ``γ ≠ 1``.
  ``γ = 2`` is GGX; ``γ < 2`` has longer tails (the corpus draws 1.2–1.9). Shadowing is GGX's
  height-correlated Smith ``G2`` at the same α (an approximation for γ ≠ 2).
* Very sharp lobes: ``γ = 2`` with roughness ``α`` ≤ 0.02.
* Retro-reflection (dust, road paint, rough clay): a GGX lobe around the *back vector*
  ``b ∝ ωi + R(ωo)``, ``R`` the mirror about the normal (Belcour, Pacanowski, Delahaie,
  Laville-Mery & Eichholzer 2014, "BRDF measurements and analysis of retroreflective materials",
  JOSA A 31(12)); ``cos θb = (μi + μo) / |ωi + R(ωo)|`` and ``ωi·b`` are symmetric in i, o.

Energy: the lobes' directional albedo ``E(μ, λ)`` is integrated per material (half-vector and
hemisphere quadratures); if ``max E > 1`` both lobes are scaled down, then the diffuse base is
coupled with Kelemen & Szirmay-Kalos 2001 so the total albedo is ``E + ρ (1 − E) ≤ 1``.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from specgen_addon.corpus.fresnel import fresnel_dielectric
from specgen_addon.corpus.material import COS_NODES, Dielectric, Reflectance, _lerp_nodes
from specgen_addon.corpus.microfacet import cosine_weighted_mean, ggx_d, lookup_mu
from specgen_addon.corpus.families.base import (ALBEDO_WAVELENGTHS_NM, FamilyMaterial, check_alpha, curves_at, directional_albedo,
                   halfvector_quadrature, hemisphere_quadrature, register, smith_g2)

GAMMA_RANGE = (1.1, 2.0)


def gtr_d(cos_h: np.ndarray, alpha: float, gamma: float) -> np.ndarray:
    """Burley 2012 GTR ``D`` (sr⁻¹), normalised; ``gamma = 2`` is GGX."""
    a2 = alpha * alpha
    c2 = np.asarray(cos_h, dtype=np.float64) ** 2
    if abs(gamma - 1.0) < 1e-9:
        norm = (a2 - 1.0) / (np.pi * np.log(a2))
    else:
        norm = (gamma - 1.0) * (a2 - 1.0) / (np.pi * (1.0 - a2 ** (1.0 - gamma)))
    return np.where(c2 > 0.0, norm / (1.0 + (a2 - 1.0) * c2) ** gamma, 0.0)


def back_vector_cosines(cos_i, cos_o, cos_d) -> tuple[np.ndarray, np.ndarray]:
    """``(cos θb, ωi·b)`` of the back vector ``b ∝ ωi + R(ωo)`` from the four isotropic cosines.

    ``ωi·ωo = cos 2θd = 2 cos²θd − 1`` and ``ωi·R(ωo) = 2 μi μo − ωi·ωo``.
    """
    i_dot_ro = 2.0 * cos_i * cos_o - (2.0 * cos_d * cos_d - 1.0)
    norm = np.sqrt(np.maximum(2.0 + 2.0 * i_dot_ro, 1e-12))
    return (cos_i + cos_o) / norm, np.clip((1.0 + i_dot_ro) / norm, 0.0, 1.0)


@register
@dataclass(frozen=True)
class Lobes(FamilyMaterial):
    """GTR(``alpha``, ``gamma``) specular on ``interface`` + optional retro lobe + diffuse base."""

    alpha: float = 0.1
    gamma: float = 2.0
    interface: Dielectric = Dielectric(1.5, 0.004)
    diffuse: Reflectance | None = None
    retro_weight: float = 0.0
    retro_alpha: float = 0.3
    family: ClassVar[str] = "lobes"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_alpha(self.name, self.alpha, self.retro_alpha)
        if not GAMMA_RANGE[0] <= self.gamma <= GAMMA_RANGE[1]:
            raise ValueError(f"GTR γ {self.gamma} outside {GAMMA_RANGE}")
        if not 0.0 <= self.retro_weight <= 1.0:
            raise ValueError(f"retro weight {self.retro_weight} outside [0, 1]")

    @property
    def kind(self) -> str:
        if self.retro_weight > 0:
            return "lobes/retro"
        if self.alpha <= 0.02:
            return "lobes/sharp"
        return "lobes/gtr" if self.gamma < 2.0 else "lobes/ggx"

    def _specular(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        fresnel = _lerp_nodes(_fresnel(self.interface, tuple(float(x) for x in w)), cos_d)
        g = gtr_d(cos_h, self.alpha, self.gamma) * smith_g2(cos_i, cos_o, self.alpha) / (4.0 * cos_i * cos_o)
        return fresnel * g[:, None]

    def _retro(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        cos_b, i_dot_b = back_vector_cosines(cos_i, cos_o, cos_d)
        g = ggx_d(cos_b, self.retro_alpha) * smith_g2(cos_i, cos_o, self.retro_alpha) / (4.0 * cos_i * cos_o)
        fresnel = _lerp_nodes(_fresnel(self.interface, tuple(float(x) for x in w)), i_dot_b)
        return fresnel * (self.retro_weight * g)[:, None]

    def _lobes(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        f = self._specular(cos_i, cos_o, cos_h, cos_d, w)
        if self.retro_weight > 0:
            f += self._retro(cos_i, cos_o, cos_h, cos_d, w)
        return f

    def _spectral(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        scale, e, diffuse_scale = _coupling(self, tuple(float(x) for x in w))
        f = self._lobes(cos_i, cos_o, cos_h, cos_d, w) * scale
        if diffuse_scale is not None:
            f += (1.0 - lookup_mu(e, cos_i)) * (1.0 - lookup_mu(e, cos_o)) * diffuse_scale
        return f


@functools.lru_cache(maxsize=256)
def _fresnel(interface: Dielectric, w: tuple[float, ...]) -> np.ndarray:
    return np.ascontiguousarray(fresnel_dielectric(COS_NODES[:, None], interface.ior(np.asarray(w))).T)


def lobe_albedo(m: Lobes) -> np.ndarray:
    """Unscaled albedo ``E(μ, λ)`` (μ nodes × ALBEDO λ) of the specular (+ retro) lobes.

    Cached on the lobes alone (name and diffuse dropped): a recoloured copy of a material
    (:mod:`specgen_addon.train.recolour`) reuses its original's quadrature."""
    return _lobe_albedo(dataclasses.replace(m, name="", split="train", diffuse=None))


@functools.lru_cache(maxsize=4096)
def _lobe_albedo(m: Lobes) -> np.ndarray:
    e = directional_albedo(m._specular, halfvector_quadrature(m.alpha), ALBEDO_WAVELENGTHS_NM)
    if m.retro_weight > 0:
        e += directional_albedo(m._retro, hemisphere_quadrature(), ALBEDO_WAVELENGTHS_NM)
    return e


@functools.lru_cache(maxsize=4096)
def _coupling(m: Lobes, w: tuple[float, ...]):
    e = lobe_albedo(m)
    scale = 1.0 / max(1.0, float(e.max()) / 0.999)
    if m.diffuse is None:
        return scale, None, None
    curves = np.clip(curves_at(e * scale, np.asarray(w)), 0.0, 0.999)
    return scale, curves, m.diffuse.at(np.asarray(w)) / (np.pi * (1.0 - cosine_weighted_mean(curves)))
