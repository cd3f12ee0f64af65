"""Stand-in materials for the model/training tests: closed-form, spectral, cheap.

A Lambertian base whose albedo ramps linearly with wavelength plus a GGX lobe
(:class:`specgen_addon.render.analytic.GGXReflector`), and a synthetic "sphere image" that is
a deterministic function of the material, so tests do not depend on the corpus or renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from specgen_addon.render.analytic import GGXReflector


@dataclass
class RampMaterial:
    """``f_r = (a + b·(λ−380)/400)/π + GGX(alpha, f0)``; RGB path uses the mean albedo."""

    a: float = 0.2
    b: float = 0.5
    alpha: float = 0.15
    f0: float = 0.04

    def _spec(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        ggx = GGXReflector(alpha=self.alpha, f0=self.f0, kd=0.0, kd_rgb=(0.0, 0.0, 0.0))
        return ggx.eval_rgb(wi, wo)[:, 0]

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        wi = np.asarray(wi, dtype=np.float64).reshape(-1, 3)
        wo = np.asarray(wo, dtype=np.float64).reshape(-1, 3)
        lam = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        rho = self.a + self.b * (lam - 380.0) / 400.0
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * (rho[None, :] / np.pi + self._spec(wi, wo)[:, None])

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        mean = self.eval(wi, wo, np.linspace(380, 780, 9)).mean(axis=1)
        return np.repeat(mean[:, None], 3, axis=1)

    def image(self, size: int = 64) -> np.ndarray:
        """A (3, size, size) 'input image' that encodes the parameters (not a render)."""
        y, x = np.mgrid[-1:1:size * 1j, -1:1:size * 1j]
        disk = (x ** 2 + y ** 2 <= 1).astype(np.float32)
        chans = [self.a + 0 * x, self.b * (1 - x ** 2), np.exp(-(x ** 2 + y ** 2) / max(self.alpha, 1e-3))]
        return (np.stack(chans) * disk).astype(np.float32)
