"""The photo-only baselines: an analytic RGB BRDF fitted to one sphere photo under known lighting
(:mod:`specgen_addon.generate.analytic_fit`), its colours uplifted to spectra.

What a real alternative to SpecGen would do with the same single photograph: fit a Principled-style
analytic BRDF to the sphere under the input's lighting, then uplift its colours to spectra
(:func:`uplift_fit`, colour-science, so not for Blender).
"""

from __future__ import annotations

import numpy as np

from specgen_addon.generate.analytic_fit import (  # noqa: F401
    ALPHA_GRID,
    COAT_ALPHA_GRID,
    COAT_F0,
    COEFFICIENTS,
    AnalyticRGB,
    AnalyticSpectral,
    PhotoFit,
    basis_lobes,
    fit_photo,
    nnls,
    observed_pixels,
)
from specgen_addon.evaluation.baselines import uplift_albedo


def uplift_fit(brdf: AnalyticRGB, method: str, wavelengths_nm: np.ndarray) -> AnalyticSpectral:
    """The spectral BRDF of a fit: its diffuse and F0 colours uplifted by ``method``
    (:func:`specgen_addon.evaluation.baselines.uplift_albedo`; colour-science, so not for Blender)."""
    wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
    spectra = uplift_albedo(np.array([brdf.diffuse, brdf.f0]), method, wl)
    return AnalyticSpectral(wl, spectra[0], spectra[1], brdf.alpha, brdf.edge, brdf.coat, brdf.coat_alpha)
