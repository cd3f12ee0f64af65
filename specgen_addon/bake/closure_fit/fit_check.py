"""How a closure fit renders: the colour error a user sees, not a residual.

The closure fit (:mod:`.closures`) minimises a weighted residual over the table's entries; what
matters in a picture is the colour of the rendered surface. This module renders the table and the
fitted closure model with the reference renderer (:mod:`specgen_addon.render`) on a sphere under
a few distant D65 lights, one at a time, and returns the worst light's mean CIEDE2000 between the
two sRGB images (colour-science). The Full Scene render reports it per material and warns above
:data:`WARN_DELTA_E`.
"""

from __future__ import annotations

import numpy as np
from specgen_addon.render import DistantLight, render_spectral, sphere_geometry
from specgen_addon.render.photo_reproduction import delta_e2000, photo_scale
from specgen_addon.render.spectral_exr import linear_srgb_preview

#: Directions towards the check lights (camera along +z): the bench's sun, head-on, and a raking
#: light from the side, so small, medium and large half angles θd are all seen.
CHECK_LIGHTS = ((0.35, 0.45, 0.82), (0.0, 0.0, 1.0), (-0.8, 0.3, 0.35))
#: Sphere size of the check (pixels across).
CHECK_RESOLUTION = 64
#: Rendered error (mean CIEDE2000) above which a material is named in a warning.
WARN_DELTA_E = 2.0


class FitBRDF:
    """A :class:`~.closures.ClosureFit` as a spectral BRDF of the reference renderer."""

    def __init__(self, fit):
        self.fit = fit

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        return self.fit.at(wavelengths_nm).eval(wi, wo)


def rendered_fit_error(fit, table, resolution: int = CHECK_RESOLUTION) -> float:
    """Worst mean ΔE2000 over :data:`CHECK_LIGHTS` between ``table`` (a spectral
    :class:`~specgen_addon.brdf.table.BRDFTable`) and its closure ``fit``, each rendered on a sphere
    under one D65 sun at the fit's bands; the level is the table render's (0 for a black table)."""
    wl = np.asarray(fit.wavelengths_nm, np.float64)
    geo = sphere_geometry(resolution)
    worst = 0.0
    for direction in CHECK_LIGHTS:
        d = np.asarray(direction, np.float64)
        lights = [DistantLight(tuple(d / np.linalg.norm(d)), np.pi)]
        ref = render_spectral(table, geo, lights=lights, wavelengths_nm=wl).spectral
        got = render_spectral(FitBRDF(fit), geo, lights=lights, wavelengths_nm=wl).spectral
        mask = ref.sum(-1) > 0
        if not mask.any():
            continue
        a, b = linear_srgb_preview(ref, wl)[mask], linear_srgb_preview(got, wl)[mask]
        de = delta_e2000(a, b, photo_scale(a))
        worst = max(worst, 0.0 if de is None else float(de))
    return worst
