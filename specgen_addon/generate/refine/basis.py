"""The correction basis of the refinement: piecewise-linear hats over θh, θd and λ.

The refined table is (see :mod:`specgen_addon.generate.refine`)

    f'(θh, θd, φd, λ) = c'(λ) + [f(θh, θd, φd, λ) − c(λ)] · Φ(θh, θd, λ),
    Φ(θh, θd, λ)      = Σ_abl x_abl · h_a(θh) g_b(θd) s_l(λ),
    c'(λ)             = c(λ) Σ_l y_l s_l(λ) + Σ_l z_l s_l(λ) / π,

where ``c(λ)`` is the network table's diffuse floor (its Lambertian part), ``h_a`` are hats over the
MERL θh index (the √ warp puts half the knots inside the first 15° where specular lobes live),
``g_b`` hats over θd (Fresnel bands) and ``s_l`` three spectral functions: by default Mallett &
Yuksel's (2019) reflectance basis (colour-science's, precomputed in ``colour_tables``), smooth
spectra of real reflectance shape whose blue, green and red members uplift the sRGB primaries;
``spectral="hats"`` gives piecewise-linear hats at 450, 550 and 630 nm instead. A photo constrains
three spectral degrees of freedom, and a correction in the Mallett basis spends them on the
smoothest, most reflectance-like change of the network's spectra that explains it; hats bend the
spectra piecewise-linearly, which matched the photo as well but cost spectral accuracy in other
lighting (docs/refinement.md). Every family is a partition of unity, so ``x = y = 1, z = 0`` is
the identity and ``x, y, z ≥ 0`` keeps ``Φ`` and ``c'`` non-negative.

* tinting the specular lobe apart from the diffuse body: ``x`` (lobe) and ``y, z`` (body) are separate;
* overall brightness: all of them;
* sharpening or widening the lobe: ``x`` varies over θh rings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.brdf.table import N_THETA_D, N_THETA_H
from specgen_addon.spectral.colour_tables import mallett2019_basis

#: θh knots as MERL grid indices (index i ↔ θh = (i/90)² · π/2): 0°, 0.5°, 1.1°, 2.2°, 4°, 6.9°,
#: 11.4°, 18.7°, 28.9°, 46.9°, 88°. The first step spans a peak the photo cannot resolve: one pixel
#: of the 128² sphere turns the normal by ≈ 0.9° at its centre, and the knots at 0.04° and 0.2°
#: (the earlier default) let the fit set a peak height no pixel determines (a refined
#: peak 3× too bright under a light the photo never saw; docs/refinement.md).
THETA_H_KNOTS = (0, 7, 10, 14, 19, 25, 32, 41, 51, 65, 89)
#: θd knots as grid indices (index j ↔ θd = j · 1°): 0°, 30°, 50°, 65°, 77°, 89°.
THETA_D_KNOTS = (0, 30, 50, 65, 77, 89)
#: Wavelength knots (nm) of ``spectral="hats"``, near the peaks of the sRGB primaries' sensitivities:
#: a photo constrains three spectral degrees of freedom, so three functions are what it can resolve.
WAVELENGTH_KNOTS_NM = (450.0, 550.0, 630.0)
#: Spectral functions of the correction: ``"mallett2019"`` (default) or ``"hats"``.
SPECTRAL_BASES = ("mallett2019", "hats")


def hat_matrix(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Piecewise-linear hats (len(x), len(knots)), constant beyond the end knots; rows sum to 1."""
    x = np.asarray(x, dtype=np.float64)
    knots = np.asarray(knots, dtype=np.float64)
    if knots.ndim != 1 or knots.size < 1 or np.any(np.diff(knots) <= 0):
        raise SpecGenError("hat knots must be a non-empty increasing sequence")
    if knots.size == 1:
        return np.ones((x.size, 1))
    eye = np.eye(knots.size)
    return np.stack([np.interp(x, knots, eye[k]) for k in range(knots.size)], axis=1)


@dataclass(frozen=True)
class CorrectionBasis:
    """Knots of the θh and θd hat families (MERL grid indices) and the spectral functions (λ in nm)."""

    theta_h_knots: tuple[float, ...] = THETA_H_KNOTS
    theta_d_knots: tuple[float, ...] = THETA_D_KNOTS
    wavelength_knots_nm: tuple[float, ...] = WAVELENGTH_KNOTS_NM
    spectral: str = "mallett2019"

    def __post_init__(self) -> None:
        if self.spectral not in SPECTRAL_BASES:
            raise SpecGenError(f"unknown spectral correction basis {self.spectral!r} "
                               f"(choose from {', '.join(SPECTRAL_BASES)})")
        if self.spectral == "mallett2019" and len(self.wavelength_knots_nm) != 3:
            raise SpecGenError("the Mallett 2019 spectral basis has three members (blue, green, red)")
        for name, knots, n in (("θh", self.theta_h_knots, N_THETA_H), ("θd", self.theta_d_knots, N_THETA_D)):
            k = np.asarray(knots, dtype=np.float64)
            if (k.ndim != 1 or k.size < 1 or np.any(k != np.round(k)) or np.any(k < 0) or np.any(k > n - 1)
                    or np.any(np.diff(k) <= 0)):
                raise SpecGenError(f"{name} knots must be increasing grid indices, whole numbers in 0…{n - 1}; "
                                   f"got {tuple(knots)}")

    @property
    def shape(self) -> tuple[int, int, int]:
        """(Na, Nb, L): θh hats, θd hats, spectral hats."""
        return len(self.theta_h_knots), len(self.theta_d_knots), len(self.wavelength_knots_nm)

    @property
    def n_lobe(self) -> int:
        na, nb, nl = self.shape
        return na * nb * nl

    def theta_h_hats(self) -> np.ndarray:
        """(90, Na) hat values at the θh grid nodes."""
        return hat_matrix(np.arange(N_THETA_H), self.theta_h_knots)

    def theta_d_hats(self) -> np.ndarray:
        """(90, Nb) hat values at the θd grid nodes."""
        return hat_matrix(np.arange(N_THETA_D), self.theta_d_knots)

    def spectral_hats(self, wavelengths_nm: np.ndarray) -> np.ndarray:
        """(Λ, L) spectral functions at the table's wavelengths (nm), rows summing to 1; for the
        Mallett basis in the order blue, green, red (like the hat knots), held beyond 380–780 nm."""
        if self.spectral == "hats":
            return hat_matrix(wavelengths_nm, self.wavelength_knots_nm)

        return mallett2019_basis(wavelengths_nm)[:, ::-1]

    def lobe_factor(self, x: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        """Φ on the grid nodes, (90, 90, Λ), for lobe coefficients ``x`` (Na, Nb, L)."""
        x = np.asarray(x, dtype=np.float64).reshape(self.shape)
        return np.einsum("ia,jb,abl,kl->ijk", self.theta_h_hats(), self.theta_d_hats(), x,
                         self.spectral_hats(wavelengths_nm), optimize=True)
