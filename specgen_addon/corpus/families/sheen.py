"""Sheen over a diffuse base: velvet, satin, felt and other cloth, dust.

Sheen lobe: the "Charlie" distribution of Estevez & Kulla 2017 ("Production Friendly Microfacet
Sheen BRDF", Sony Pictures Imageworks), an inverted-Gaussian-like fibre distribution

``D(θh) = (2 + 1/r) sin^{1/r}(θh) / (2π)``,   roughness ``r`` ∈ (0, 1],

with the closed-form visibility of Neubelt & Pettineo 2013 ("Crafting a Next-Gen Material
Pipeline for The Order: 1886"), ``V = 1 / (4 (μi + μo − μi μo))``, so ``f_sheen = D V``, which is
symmetric in i, o. The lobe's directional albedo ``E_s(μ)`` is integrated (hemisphere quadrature);
if it exceeds 1 anywhere the lobe is scaled down to 1. The sheen is tinted by a spectrum ``s(λ)``
(≤ 1), and the diffuse base ``ρ(λ)`` is coupled with Kelemen & Szirmay-Kalos 2001:

``f = s f_sheen + ρ/π (1 − s E_s(μi)) (1 − s E_s(μo)) / (1 − s Ē_s)``, albedo ``s E_s + ρ (1 − s E_s) ≤ 1``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from specgen_addon.corpus.material import Reflectance
from specgen_addon.corpus.microfacet import MU_NODES, cosine_weighted_mean, lookup_mu
from specgen_addon.corpus.families.base import FamilyMaterial, directional_albedo, hemisphere_quadrature, register

ROUGHNESS_RANGE = (0.05, 1.0)


def charlie_d(cos_h: np.ndarray, roughness: float) -> np.ndarray:
    """Estevez & Kulla 2017 ``D`` (sr⁻¹) at half-vector cosine ``cos_h``."""
    sin_h = np.sqrt(np.clip(1.0 - np.asarray(cos_h, dtype=np.float64) ** 2, 0.0, 1.0))
    inv = 1.0 / roughness
    return (2.0 + inv) * sin_h ** inv / (2.0 * np.pi)


def sheen_lobe(cos_i, cos_o, cos_h, roughness: float) -> np.ndarray:
    """``D V`` with Neubelt & Pettineo's visibility, without scaling or tint (N,)."""
    return charlie_d(cos_h, roughness) / (4.0 * (cos_i + cos_o - cos_i * cos_o))


@functools.lru_cache(maxsize=4096)  # one per corpus roughness: a smaller cache thrashes every step
def sheen_albedo(roughness: float) -> np.ndarray:
    """``E_s(μ)`` at :data:`MU_NODES` of the unscaled lobe (hemisphere quadrature)."""
    fn = lambda ci, co, ch, cd, w: sheen_lobe(ci, co, ch, roughness)[:, None]  # noqa: E731
    return directional_albedo(fn, hemisphere_quadrature(), np.array([550.0]))[:, 0]


@register
@dataclass(frozen=True)
class Sheen(FamilyMaterial):
    """Charlie sheen of ``roughness`` tinted by ``sheen_color`` over a diffuse ``base_color``."""

    roughness: float = 0.5
    sheen_color: Reflectance | None = None
    base_color: Reflectance | None = None
    family: ClassVar[str] = "sheen"

    def __post_init__(self) -> None:
        super().__post_init__()
        if not ROUGHNESS_RANGE[0] <= self.roughness <= ROUGHNESS_RANGE[1]:
            raise ValueError(f"sheen roughness {self.roughness} outside {ROUGHNESS_RANGE}")
        if self.sheen_color is None or self.base_color is None:
            raise ValueError("sheen needs a sheen colour and a base colour")

    def _spectral(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        scale, s, e_curves, diffuse_scale = _tables(self, tuple(float(x) for x in w))
        f = (scale * sheen_lobe(cos_i, cos_o, cos_h, self.roughness))[:, None] * s
        f += (1.0 - lookup_mu(e_curves, cos_i)) * (1.0 - lookup_mu(e_curves, cos_o)) * diffuse_scale
        return f


@functools.lru_cache(maxsize=4096)
def _tables(m: Sheen, w: tuple[float, ...]):
    e = sheen_albedo(float(m.roughness))
    scale = 1.0 / max(1.0, float(e.max()))
    wa = np.asarray(w)
    s = m.sheen_color.at(wa)
    curves = np.clip(s[:, None] * (scale * e)[None, :], 0.0, 0.999)  # (Λ, μ)
    diffuse_scale = m.base_color.at(wa) / (np.pi * (1.0 - cosine_weighted_mean(curves)))
    assert curves.shape[1] == MU_NODES.size
    return scale, s, curves, diffuse_scale
