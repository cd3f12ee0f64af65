"""The sphere's silhouette to a fraction of a pixel.

A photographed or antialiased sphere's outline pixels are partly covered: each holds the sphere's
colour weighted by the fraction of its area inside the disc. Counting them as whole pixels makes
the sphere about half a pixel too large, and the network (trained on exactly framed spheres)
loses several dB for a 1 % error in scale (lab/notebook/resampled-network.md, "Where the sphere
sits").

:func:`refine_circle` measures that coverage. Per angular sector, the area the disc covers in a
thin band across the outline is the sum of the band pixels' coverages, each the pixel's contrast
against the background divided by the sphere's own contrast there: extrapolated along the same ray
from two points just inside the band, so that shading that darkens or brightens towards the limb
is not mistaken for partial cover. The sector's edge radius follows from the area of an annular
sector, (R² − ρ_in²)·Δφ/2, and a least-squares circle through the sector edges (outliers dropped)
is the refined circle. This is exact for box-filtered (area-sampled) pixels and unbiased on average
for point-sampled ones.
Measured on the six families' held-out spheres, exactly framed, antialiased and half a pixel off
the grid: radius within 0.09 px rms and centre within 0.06 px rms (out of 64 px).

Pixel coordinates throughout: x to the right, y down, pixel (i, j)'s centre at (j + 0.5, i + 0.5).
Numpy only (a stock Blender's panel path).
"""

from __future__ import annotations

import numpy as np

from specgen_addon.photo.ndimage_np import fit_circle, map_coordinates

#: Sectors of the outline that :func:`refine_circle` measures separately.
SECTORS = 72
#: Half-width (pixels) of the band across the outline whose coverage is summed.
BAND_PX = 1.0
#: A sector whose inside contrast is below this fraction of the sphere's median contrast is not
#: measured (a black limb on a black background has no edge to see).
MIN_REFERENCE_FRACTION = 0.1


def _bilinear(a: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``a`` sampled at pixel coordinates (x, y) (centres at +0.5), edges replicated."""
    return map_coordinates(a, [y - 0.5, x - 0.5], order=1, mode="nearest")


def _least_squares_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Algebraic (Kåsa) least-squares circle through points: (cx, cy, r)."""
    cx, cy, r = fit_circle(np.stack([x, y], -1))
    return float(cx), float(cy), float(r)


def sector_edges(contrast: np.ndarray, cx: float, cy: float, r: float,
                 sectors: int = SECTORS, band_px: float = BAND_PX) -> tuple[np.ndarray, np.ndarray]:
    """Edge radius (pixels) of each angular sector about (cx, cy), and which sectors were measured.

    ``contrast``: (H, W), the pixel's departure from the background, linear in its coverage (0 on
    the background). ``r``: the outline's radius to within about a pixel.
    """
    h, w = contrast.shape
    inner = r - band_px
    outer = r + band_px
    x0, x1 = max(int(cx - outer) - 1, 0), min(int(cx + outer) + 2, w)
    y0, y1 = max(int(cy - outer) - 1, 0), min(int(cy + outer) + 2, h)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    px, py = xx + 0.5 - cx, yy + 0.5 - cy
    rho = np.hypot(px, py)
    inside = contrast[y0:y1, x0:x1][rho < inner - 1.0]
    typical = float(np.median(inside)) if inside.size else 0.0   # the sphere's own contrast
    band = (rho >= inner) & (rho < outer)
    px, py, rho = px[band], py[band], rho[band]
    value = contrast[y0:y1, x0:x1][band]
    # the reference: the sphere's contrast on the same ray, one and two pixels inside the band
    ux, uy = px / rho, py / rho
    ref_a = _bilinear(contrast, cx + ux * (inner - 1.0), cy + uy * (inner - 1.0))
    # the shading's slope towards the limb, from two points inside
    ref_b = _bilinear(contrast, cx + ux * (inner - 2.0), cy + uy * (inner - 2.0))
    ref = np.clip(ref_a + (ref_a - ref_b) * (rho - (inner - 1.0)), 0.5 * ref_a, 2.0 * ref_a)
    ok = ref > MIN_REFERENCE_FRACTION * typical
    coverage = np.clip(value / np.where(ok, ref, 1.0), 0.0, 1.0)
    sector = np.minimum(((np.arctan2(py, px) + np.pi) / (2 * np.pi) * sectors).astype(int), sectors - 1)
    area = np.bincount(sector, weights=coverage, minlength=sectors)
    count = np.bincount(sector, minlength=sectors)
    measured = (np.bincount(sector, weights=ok, minlength=sectors) == count) & (count > 0)
    dphi = 2 * np.pi / sectors
    radius = np.sqrt(inner * inner + 2.0 * area / dphi)
    return radius, measured


def refine_circle(contrast: np.ndarray, cx: float, cy: float, r: float,
                  iterations: int = 2) -> tuple[float, float, float] | None:
    """The circle (cx, cy, r) in pixels refined to a fraction of a pixel from the outline's
    coverage (module docstring), or None when too little of the outline can be measured."""
    sectors = SECTORS
    phi = (np.arange(sectors) + 0.5) / sectors * 2 * np.pi - np.pi
    for _ in range(iterations):
        radius, measured = sector_edges(contrast, cx, cy, r, sectors)
        ex, ey = cx + radius * np.cos(phi), cy + radius * np.sin(phi)
        keep = measured.copy()
        for _ in range(2):  # drop sectors off the circle (a stand, a shadow, a dark limb)
            if keep.sum() < sectors // 3:
                return None
            fx, fy, fr = _least_squares_circle(ex[keep], ey[keep])
            resid = np.abs(np.hypot(ex - fx, ey - fy) - fr)
            keep = measured & (resid < max(0.5, 3.0 * float(np.median(resid[keep]))))
        if keep.sum() < sectors // 3:
            return None
        cx, cy, r = _least_squares_circle(ex[keep], ey[keep])
    return cx, cy, r
