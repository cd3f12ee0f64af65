"""Distant (directional) lights with spectral irradiance ``E · S_illuminant(λ)``.

A distant light arriving from unit direction ``ω_l`` (world, pointing *towards* the light) with
irradiance ``E`` (on a surface facing it) adds ``f_r(ω_l, ω_o, λ) · E · S(λ) · max(0, n·ω_l)`` to the
outgoing radiance. ``S`` is :func:`specgen_addon.spectral.spectra.illuminant_spd`, normalised to unit
luminance, so a white Lambertian facing a light of ``E = π`` has radiance with ``Y = 1``.
No shadowing: the renderer's surfaces are convex (a sphere) or treated as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError


@dataclass(frozen=True)
class DistantLight:
    """A directional light.

    Parameters
    ----------
    direction
        World direction towards the light (normalised on use).
    irradiance
        ``E`` in W·m⁻² (relative units): irradiance on a surface facing the light.
    illuminant
        Name of a CIE illuminant known to colour-science (``"D65"``, ``"A"``, ``"F2"``, ...).
    """

    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    irradiance: float = float(np.pi)
    illuminant: str = spectra.DEFAULT_ILLUMINANT

    def unit_direction(self) -> np.ndarray:
        """Normalised direction towards the light, shape (3,)."""
        d = np.asarray(self.direction, dtype=np.float64)
        norm = np.linalg.norm(d)
        if not np.isfinite(norm) or norm == 0:
            raise SpecGenError(f"distant light direction {self.direction} is not a valid vector")
        return d / norm

    def spectrum(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """Spectral irradiance ``E · S(λ)`` at ``wavelengths_nm``, shape (Λ,)."""
        return self.irradiance * spectra.illuminant_spd(self.illuminant, wavelengths_nm)

    def rgb(self) -> np.ndarray:
        """Linear-sRGB irradiance of the light (the same spectrum seen by the renderer's camera).

        Integrated on a fine 5 nm grid and white-balanced to D65 as the spectral path is, so D65
        light of irradiance ``E`` is ``(E, E, E)``.
        """
        grid = spectra.wavelength_grid(380.0, 780.0, 81)
        return spectra.spectral_to_linear_srgb(self.spectrum(grid), grid)
