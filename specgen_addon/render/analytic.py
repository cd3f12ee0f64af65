"""Two closed-form BRDFs for checking the renderer against independent truths.

:class:`Lambertian` (``f_r = ρ(λ)/π``) and :class:`GGXReflector` (a Lambertian base plus a
Cook–Torrance GGX lobe with Schlick Fresnel, Walter et al. 2007, "Microfacet Models for Refraction
through Rough Surfaces", EGSR). They follow the project's BRDF protocol: ``eval(wi, wo, λ) -> (N, Λ)``
and ``eval_rgb(wi, wo) -> (N, 3)``, local frame with the normal on +z, zero below the horizon.
The real materials live in :mod:`specgen_addon.corpus`; these exist so renderer tests and benches
do not depend on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _spectrum(value: float | np.ndarray | tuple, wavelengths_nm: np.ndarray | None,
              value_wavelengths_nm: np.ndarray | None) -> np.ndarray:
    v = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if v.size == 1 or wavelengths_nm is None:
        return v if wavelengths_nm is None else np.full(len(np.atleast_1d(wavelengths_nm)), v[0])
    if value_wavelengths_nm is None:
        if v.size != len(wavelengths_nm):
            raise ValueError("spectrum length differs from the wavelength grid")
        return v
    return np.interp(wavelengths_nm, value_wavelengths_nm, v)


def _above(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    return (wi[..., 2] > 0) & (wo[..., 2] > 0)


@dataclass
class Lambertian:
    """``f_r = ρ/π``. ``albedo`` is a scalar, a spectrum on ``albedo_wavelengths_nm``, or RGB in ``rgb``."""

    albedo: float | np.ndarray = 1.0
    albedo_wavelengths_nm: np.ndarray | None = None
    rgb: tuple[float, float, float] | None = None

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        rho = _spectrum(self.albedo, np.atleast_1d(wavelengths_nm), self.albedo_wavelengths_nm)
        return _above(wi, wo)[:, None] * (rho / np.pi)[None, :]

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        rgb = np.asarray(self.rgb if self.rgb is not None else np.full(3, float(np.mean(self.albedo))))
        return _above(wi, wo)[:, None] * (rgb / np.pi)[None, :]


@dataclass
class GGXReflector:
    """Lambertian base ``kd`` + GGX specular lobe of roughness ``alpha`` and normal-incidence
    reflectance ``f0`` (Schlick). Scalars are spectrally flat; ``kd_rgb`` colours the RGB path."""

    alpha: float = 0.2
    f0: float = 0.04
    kd: float = 0.5
    kd_rgb: tuple[float, float, float] = (0.5, 0.5, 0.5)

    def _specular(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        a2 = self.alpha ** 2
        cos_h = h[..., 2]
        d = a2 / (np.pi * ((cos_h ** 2) * (a2 - 1.0) + 1.0) ** 2)

        def g1(w: np.ndarray) -> np.ndarray:
            c = np.clip(w[..., 2], 1e-9, 1.0)
            tan2 = (1.0 - c * c) / (c * c)
            return 2.0 / (1.0 + np.sqrt(1.0 + a2 * tan2))

        vh = np.clip(np.sum(wo * h, -1), 0.0, 1.0)
        f = self.f0 + (1.0 - self.f0) * (1.0 - vh) ** 5
        denom = 4.0 * np.clip(wi[..., 2], 1e-9, None) * np.clip(wo[..., 2], 1e-9, None)
        return f * d * g1(wi) * g1(wo) / denom

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        n_bands = len(np.atleast_1d(wavelengths_nm))
        fr = self.kd / np.pi + self._specular(wi, wo)
        return np.repeat((_above(wi, wo) * fr)[:, None], n_bands, axis=1)

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        fr = np.asarray(self.kd_rgb)[None, :] / np.pi + self._specular(wi, wo)[:, None]
        return _above(wi, wo)[:, None] * fr
