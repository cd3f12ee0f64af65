"""Thin-film interference over a dielectric or a metal: soap and oil films, anodised titanium,
coated lenses, beetle shells.

The film (index ``η_f``, thickness ``d`` in nm) sits on a substrate of index ``n₂`` (real Cauchy
dielectric or measured complex metal index). Its reflectance is the exact Airy summation of the
multiply reflected waves, per polarisation and per wavelength (Born & Wolf, *Principles of
Optics*, 7th ed., §1.6.4, eq. 58; the model Belcour & Barla 2017, "A Practical Extension to
Microfacet Theory for the Modeling of Varying Iridescence", approximate for speed):

``r = (r₀₁ + r₁₂ e^{iδ}) / (1 + r₀₁ r₁₂ e^{iδ})``,  ``δ = 4π η_f d cos θ₁ / λ``,
``R = (|r_s|² + |r_p|²) / 2``,

with ``r_ij`` the Fresnel amplitude coefficients of the two interfaces and ``θ₁`` the angle in
the film. ``d = 0`` gives the bare substrate's Fresnel reflectance exactly, a quarter-wave film
with ``η_f = √n₂`` gives zero at normal incidence (both are tests).

``R(θd, λ)`` replaces the Fresnel factor of a GGX microfacet lobe (Walter et al. 2007). Over a
dielectric, an optional diffuse base ``ρ(λ)`` is coupled with Kelemen & Szirmay-Kalos 2001 using
the lobe's own directional albedo (integrated by quadrature), so the albedo stays ≤ 1.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from specgen_addon.corpus.fresnel import cauchy_ior
from specgen_addon.corpus.material import COS_NODES, Conductor, Dielectric, Reflectance, _lerp_nodes
from specgen_addon.corpus.metals import metal_ior
from specgen_addon.corpus.microfacet import cosine_weighted_mean, lookup_mu, specular_geometry
from specgen_addon.corpus.families.base import (ALBEDO_WAVELENGTHS_NM, FamilyMaterial, check_alpha, curves_at, directional_albedo,
                   halfvector_quadrature, register)

#: Film thickness range (nm) the corpus draws from, and film indices (oil, soap ≈ 1.33–1.5; oxides up to 2.4).
THICKNESS_RANGE_NM = (0.0, 1500.0)


def film_amplitudes(cos0: np.ndarray, n1: np.ndarray, n2: np.ndarray):
    """Fresnel amplitude coefficients (s, p) of the air/film (0→1) and film/substrate (1→2) interfaces."""
    sin2 = 1.0 - cos0 * cos0
    cos1 = np.sqrt(1.0 - sin2 / (n1 * n1) + 0j)
    cos2 = np.sqrt(1.0 - sin2 / (n2 * n2) + 0j)
    r01s = (cos0 - n1 * cos1) / (cos0 + n1 * cos1)
    r01p = (n1 * cos0 - cos1) / (n1 * cos0 + cos1)
    r12s = (n1 * cos1 - n2 * cos2) / (n1 * cos1 + n2 * cos2)
    r12p = (n2 * cos1 - n1 * cos2) / (n2 * cos1 + n1 * cos2)
    return cos1, (r01s, r12s), (r01p, r12p)


def airy_reflectance(cos_theta: np.ndarray, wavelengths_nm: np.ndarray, film_eta: float | np.ndarray,
                     thickness_nm: float, substrate_n: np.ndarray) -> np.ndarray:
    """Unpolarised reflectance of a film on a substrate, from air (Airy summation, exact).

    ``cos_theta`` (..., 1) or broadcastable against ``wavelengths_nm`` (Λ,); ``substrate_n`` real
    or complex per wavelength; ``thickness_nm`` ≥ 0 (a float, or an array broadcastable against the
    others, e.g. (N, 1, 1) for a stack of films). Returns the broadcast shape.
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    lam = np.asarray(wavelengths_nm, dtype=np.float64)
    n1 = np.asarray(film_eta, dtype=np.float64) + 0j
    n2 = np.asarray(substrate_n) + 0j
    cos1, s, p = film_amplitudes(c, n1, n2)
    phase = np.exp(1j * 4.0 * np.pi * n1 * np.asarray(thickness_nm, dtype=np.float64) * cos1 / lam)
    out = 0.0
    for r01, r12 in (s, p):
        r = (r01 + r12 * phase) / (1.0 + r01 * r12 * phase)
        out = out + 0.5 * np.abs(r) ** 2
    return np.clip(np.real(out), 0.0, 1.0)


@register
@dataclass(frozen=True)
class ThinFilm(FamilyMaterial):
    """GGX lobe with Airy thin-film Fresnel over a ``substrate``; optional diffuse (dielectric only)."""

    alpha: float = 0.1
    film_eta: float = 1.45
    thickness_nm: float = 400.0
    substrate: Dielectric | Conductor = Dielectric(1.5, 0.004)
    diffuse: Reflectance | None = None
    family: ClassVar[str] = "thin_film"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_alpha(self.name, self.alpha)
        if not (1.0 < self.film_eta < 4.0 and 0.0 <= self.thickness_nm <= 5000.0):
            raise ValueError(f"thin film η {self.film_eta} / d {self.thickness_nm} nm out of range")
        if self.diffuse is not None and not isinstance(self.substrate, Dielectric):
            raise ValueError("a metal substrate has no diffuse lobe")

    @property
    def kind(self) -> str:
        sub = f"metal:{self.substrate.metal}" if isinstance(self.substrate, Conductor) else "dielectric"
        return f"thin_film/{sub}"

    def substrate_index(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        if isinstance(self.substrate, Conductor):
            eta, k = metal_ior(self.substrate.metal, wavelengths_nm)
            return eta + 1j * k
        return cauchy_ior(wavelengths_nm, self.substrate.cauchy_a, self.substrate.cauchy_b_um2) + 0j

    def film_reflectance(self, cos_theta: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        """``R(cos θ, λ)``: shape ``cos_theta.shape + (Λ,)``."""
        w = np.asarray(wavelengths_nm, dtype=np.float64)
        return airy_reflectance(np.asarray(cos_theta)[..., None], w, self.film_eta, self.thickness_nm,
                                self.substrate_index(w))

    def _lobe(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        fresnel = _lerp_nodes(_fresnel_table(self, tuple(float(x) for x in w)), cos_d)
        return fresnel * specular_geometry(cos_i, cos_o, cos_h, self.alpha)[:, None]

    def _spectral(self, cos_i, cos_o, cos_h, cos_d, w) -> np.ndarray:
        f = self._lobe(cos_i, cos_o, cos_h, cos_d, w)
        if self.diffuse is not None:
            e, scale = _coupling(self, tuple(float(x) for x in w))
            f += (1.0 - lookup_mu(e, cos_i)) * (1.0 - lookup_mu(e, cos_o)) * scale
        return f


@functools.lru_cache(maxsize=4096)
def _fresnel_table(m: ThinFilm, w: tuple[float, ...]) -> np.ndarray:
    return np.ascontiguousarray(m.film_reflectance(COS_NODES, np.asarray(w)).T)


@functools.lru_cache(maxsize=4096)
def _coupling(m: ThinFilm, w: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Kelemen coupling: lobe albedo curves (Λ, μ) and ``ρ / (π (1 − Ē))`` at ``w``."""
    e = curves_at(_albedo(dataclasses.replace(m, name="", split="train", diffuse=None)), np.asarray(w))
    return e, m.diffuse.at(np.asarray(w)) / (np.pi * (1.0 - cosine_weighted_mean(e)))


@functools.lru_cache(maxsize=4096)
def _albedo(m: ThinFilm) -> np.ndarray:
    """The lobe's albedo curves; called with name and diffuse dropped (:func:`_coupling`), so a
    recoloured copy reuses its original's quadrature."""
    return np.clip(directional_albedo(m._lobe, halfvector_quadrature(m.alpha), ALBEDO_WAVELENGTHS_NM),
                   0.0, 0.999)
