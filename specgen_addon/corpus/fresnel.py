"""Fresnel reflectance of smooth interfaces, unpolarised light incident from air.

* Dielectric: the exact unpolarised Fresnel equations for a real relative index ``η``
  (Walter et al. 2007, eq. 22), with dispersion from Cauchy's equation ``η(λ) = A + B / λ²``
  (Cauchy 1836; ``λ`` in micrometres, ``B`` in µm²).
* Conductor: the exact unpolarised Fresnel equations for a complex index ``η + i k``
  (Born & Wolf, *Principles of Optics*, §14.2), fed with measured ``(η, k)(λ)`` spectra
  (:mod:`specgen_addon.corpus.metals`).

Angles enter as ``cos θ`` of the angle between the incident direction and the (micro)normal.
"""

from __future__ import annotations

import numpy as np


def cauchy_ior(wavelengths_nm: np.ndarray, a: float, b_um2: float) -> np.ndarray:
    """Cauchy dispersion ``η(λ) = A + B / λ²`` with ``λ`` converted from nm to µm."""
    lam_um = np.asarray(wavelengths_nm, dtype=np.float64) * 1e-3
    return a + b_um2 / lam_um ** 2


def fresnel_dielectric(cos_theta: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Unpolarised reflectance of a dielectric with relative index ``eta`` ≥ 1 (broadcasts).

    Walter et al. 2007, eq. 22: ``g = sqrt(η² − 1 + c²)``,
    ``F = ½ ((g − c)/(g + c))² (1 + ((c (g + c) − 1)/(c (g − c) + 1))²)``.
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    eta = np.asarray(eta, dtype=np.float64)
    g = np.sqrt(np.maximum(eta * eta - 1.0 + c * c, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def fresnel_conductor(cos_theta: np.ndarray, eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Unpolarised reflectance of a conductor with complex index ``eta + i k`` (broadcasts).

    Snell's law with a complex index gives the complex ``cos θt``; the s and p amplitude
    coefficients ``r_s = (c − n cos θt)/(c + n cos θt)``, ``r_p = (n c − cos θt)/(n c + cos θt)``
    are averaged in power.
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    n = np.asarray(eta, dtype=np.float64) + 1j * np.asarray(k, dtype=np.float64)
    sin2_t = (1.0 - c * c) / (n * n)
    cos_t = np.sqrt(1.0 - sin2_t)
    r_s = (c - n * cos_t) / (c + n * cos_t)
    r_p = (n * c - cos_t) / (n * c + cos_t)
    return 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)
