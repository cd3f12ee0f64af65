"""A ball in a camera photo: found from its lit outline, without a mask.

Real photos defeat a foreground threshold: the ball's unlit side merges with a dark background,
a stand touches it, the room shows behind it. What stays is the lit part of the outline, an arc
of a circle along which the brightness falls steeply across the silhouette. So:

1. **Votes** (a gradient-directed circle Hough transform): every strong edge pixel of a reduced
   copy (longer side ≤ :data:`WORK_SIDE`) votes, along its gradient, for the centres of circles of
   every radius that would pass through it with the ball on its bright side (or, for a dark ball
   on a bright ground, its dark side). The best centre and radius have the most votes per unit
   of circumference: the longest circular arc.
2. **Rays**: at full resolution, the brightness along :data:`RAYS` rays across the voted circle,
   each fitted with a model of a lit ball's outline (background, plus a step where light from the
   side keeps the rim lit to the silhouette, plus the Lambertian limb √(1 − (ρ/R)²) of light from
   the front, which fades to nothing at the silhouette; all blurred by one Gaussian shared by the
   rays; both integrated over the pixel): each ray's silhouette radius to a tenth of a pixel. Rays
   without a clear fall (the unlit side) or that the model does not explain (a stand) are dropped.
3. **Fit**: the circle the lit rim agrees with: the rays whose step (the rim lit up to the
   silhouette) is at least half the well-lit rim's, weighted by it (RANSAC over their edge
   points, tolerance a fraction of the radius, so a photo found at 512 px is found the same at
   8000 px), refitted by least squares. On the side away from the light the shading fades at a
   terminator a pixel or more inside the silhouette, which the limb term fits as readily as the
   silhouette: counted, it pulled the circle up to 1 px off on real photos. A ball lit from
   the front, with no rim lit anywhere, is fitted on every clear edge (there the terminator is
   the silhouette). A stand or a shadow lies off the circle.

Numpy only (the stock-Blender panel runs it too). Pixel coordinates: x right, y down, pixel
(i, j)'s centre at (j + 0.5, i + 0.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from specgen_addon.common.errors import ImageInputError
from specgen_addon.photo.ndimage_np import fit_circle, gaussian_filter, map_coordinates
from specgen_addon.photo.white_balance import LUMINANCE

#: Longer side of the reduced copy the votes are counted on (pixels).
WORK_SIDE = 256
#: Rays across the outline measured at full resolution.
RAYS = 360
#: Smallest radius searched, as a fraction of the image's shorter side.
MIN_RADIUS_FRACTION = 0.06
#: Residual (fraction of the radius) beyond which an edge point is off the circle.
OUTLIER_FRACTION = 0.004
#: At least this share of the outline must show a clear edge.
MIN_ARC = 0.2
#: A ray's rim counts as lit when its step is at least this fraction of the well-lit rim's (the
#: 90th percentile of the rays'): where the light grazes, the terminator nears the silhouette.
RIM_FRACTION = 0.5


@dataclass(frozen=True)
class FoundCircle:
    """A circle found in a photo: centre and radius (pixels) and the share of its outline seen."""

    cx: float
    cy: float
    r: float
    arc: float        # share of the outline where a clear edge lies on the circle (0–1)
    rms_px: float     # rms distance of those edge points from the circle (pixels)

    @property
    def circle(self) -> tuple[float, float, float]:
        return self.cx, self.cy, self.r


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of a linear RGB(A) image (H, W)."""
    return np.asarray(rgb[..., :3], np.float64) @ LUMINANCE


def _reduce(lum: np.ndarray, factor: int) -> np.ndarray:
    if factor <= 1:
        return lum
    h, w = lum.shape
    oh, ow = h // factor, w // factor
    return lum[:oh * factor, :ow * factor].reshape(oh, factor, ow, factor).mean(axis=(1, 3))


def _compressed(lum: np.ndarray) -> np.ndarray:
    """Brightness on a logarithmic scale, floored at the dark end, so the dim parts of an outline
    (a dark ball's rim, the shaded side) vote as well as the bright ones."""
    top = float(np.percentile(lum, 99.9))
    if not top > 0:
        raise ImageInputError("image is blank: no sphere found")
    floor = max(float(np.percentile(lum, 25)), 2e-3 * top)
    return np.log(np.maximum(lum, 0.0) + floor)


def _smooth_votes(acc: np.ndarray) -> np.ndarray:
    """Votes (radius, y, x) spread over neighbouring radii (1, 2, 1) and a 3×3 box of centres, so a
    circle whose votes straddle cells still peaks."""
    out = 2.0 * acc
    out[1:] += acc[:-1]
    out[:-1] += acc[1:]
    p = np.pad(out, ((0, 0), (1, 1), (1, 1)))
    out = p[:, :-2] + p[:, 1:-1] + p[:, 2:]
    return out[:, :, :-2] + out[:, :, 1:-1] + out[:, :, 2:]


def vote_circle(lum: np.ndarray, min_radius: float | None = None,
                max_radius: float | None = None) -> tuple[float, float, float, float]:
    """(cx, cy, r, score) of the best circle of the luminance image ``lum`` (full-resolution
    pixels), by gradient-directed voting on a reduced copy; ``score`` is the voted share of the
    circumference."""
    h, w = lum.shape
    factor = max(1, math.ceil(max(h, w) / WORK_SIDE))
    small = _compressed(_reduce(lum, factor))
    sh, sw = small.shape
    v = gaussian_filter(small, 1.0, mode="nearest")
    gy, gx = np.gradient(v)
    mag = np.hypot(gx, gy)
    strong = mag > max(0.25 * float(np.percentile(mag, 99.5)), 1e-6)
    ys, xs = np.nonzero(strong)
    if xs.size < 20:
        raise ImageInputError("no sphere found (no outline stands out from the background)")
    m = mag[ys, xs]
    ux, uy = gx[ys, xs] / m, gy[ys, xs] / m
    px, py = xs + 0.5, ys + 0.5
    r_lo = max(3.0, (min_radius / factor) if min_radius else MIN_RADIUS_FRACTION * min(sh, sw))
    r_hi = (max_radius / factor) if max_radius else 0.55 * max(sh, sw)
    radii = np.arange(r_lo, max(r_hi, r_lo + 1.0), 1.0)
    best = (0.0, 0.0, 0.0, -1.0)
    weight = np.sqrt(m / m.max())
    for sign in (1.0, -1.0):   # ball brighter than its background (gradient inward), or darker
        acc = np.zeros((radii.size, sh, sw))
        for k, r in enumerate(radii):
            cx = np.floor(px + sign * ux * r).astype(int)
            cy = np.floor(py + sign * uy * r).astype(int)
            ok = (cx >= 0) & (cx < sw) & (cy >= 0) & (cy < sh)
            acc[k] = np.bincount(cy[ok] * sw + cx[ok], weights=weight[ok], minlength=sh * sw).reshape(sh, sw)
        acc = _smooth_votes(acc) / (2 * np.pi * radii)[:, None, None]
        k, iy, ix = np.unravel_index(int(np.argmax(acc)), acc.shape)
        if acc[k, iy, ix] > best[3]:
            best = ((ix + 0.5) * factor, (iy + 0.5) * factor, float(radii[k]) * factor, float(acc[k, iy, ix]))
    return best


def _erf(x: np.ndarray) -> np.ndarray:
    """Error function (Abramowitz & Stegun 7.1.26, |error| < 1.5e-7): numpy has none."""
    t = 1.0 / (1.0 + 0.3275911 * np.abs(x))
    y = 1.0 - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496735) * t
               + 0.254829592) * t * np.exp(-x * x)
    return np.sign(x) * y


def _pixel_blur(t: np.ndarray, sigma: float) -> np.ndarray:
    """The edge-spread function of a pixel (a 1 px box) blurred by a Gaussian of ``sigma`` px, at
    offsets ``t`` (px) past the edge: the share of the pixel's light that comes from beyond it."""
    def ramp(x):   # ∫ Φ: x Φ(x) + φ(x)
        return x * 0.5 * (1.0 + _erf(x / np.sqrt(2.0))) + np.exp(-0.5 * x * x) / np.sqrt(2.0 * np.pi)
    return sigma * (ramp((-t + 0.5) / sigma) - ramp((-t - 0.5) / sigma))


def _limb_basis(rho: np.ndarray, radius: float, sigma: float) -> np.ndarray:
    """(n, 3) brightness across a ball's outline at radii ``rho`` for a silhouette at ``radius``,
    integrated over a pixel and blurred by a Gaussian of ``sigma`` px: background (1), a step
    (light from the side: the rim stays lit up to the silhouette) and the Lambertian limb
    √(1 − (ρ/R)²) of light from the front, which falls to 0 at the silhouette."""
    fine = np.linspace(-4.0 * sigma - 0.5, 4.0 * sigma + 0.5, 49)
    cdf = _pixel_blur(np.concatenate([[fine[0] - 0.5 * (fine[1] - fine[0])],
                                      0.5 * (fine[1:] + fine[:-1]),
                                      [fine[-1] + 0.5 * (fine[1] - fine[0])]]), sigma)
    wts = -np.diff(cdf)
    wts /= wts.sum()
    q = rho[:, None] + fine[None]
    limb = np.sqrt(np.clip(1.0 - (q / radius) ** 2, 0.0, None)) @ wts
    step = _pixel_blur(rho - radius, sigma)
    return np.stack([np.ones_like(rho), step, limb], -1)


@dataclass(frozen=True)
class RayEdges:
    """The outline measured along rays from a centre (:func:`model_edges`), one entry per ray."""

    edge: np.ndarray       # the silhouette's radius (px)
    rim: np.ndarray        # the step's height: the brightness kept up to the silhouette
    limb: np.ndarray       # the Lambertian limb's weight: brightness that fades towards the edge
    rms: np.ndarray        # rms residual of the ray's fit, relative to rim + limb
    phi: np.ndarray        # the ray's angle (radians, x right, y down)
    sigma: float           # the blur shared by all rays (px)

    @property
    def contrast(self) -> np.ndarray:
        return self.rim + self.limb


def model_edges(lum: np.ndarray, cx: float, cy: float, r: float, rays: int = RAYS,
                sigmas: tuple[float, ...] | None = None) -> RayEdges:
    """The silhouette's radius along each ray, from a model of a lit ball's outline
    (:func:`_limb_basis`) fitted per ray by least squares over candidate radii and a blur shared by
    all rays."""
    step = 0.2
    span_in, span_out = max(0.06 * r, 5.0), max(0.03 * r, 4.0)
    rho = np.arange(r - span_in - 2.0, r + span_out + 2.0, step)
    phi = (np.arange(rays) + 0.5) / rays * 2 * np.pi
    x = cx + np.cos(phi)[:, None] * rho[None]
    y = cy + np.sin(phi)[:, None] * rho[None]
    prof = map_coordinates(lum, [y - 0.5, x - 0.5], order=1, mode="nearest").T   # (n, rays)
    cands = r + np.arange(-0.5 * span_in, 0.5 * span_out + 1e-9, 0.1)
    if sigmas is None:
        sigmas = tuple(np.geomspace(0.3, max(0.012 * r, 0.8), 4))
    best = None
    for sigma in sigmas:
        res = np.empty((cands.size, rays))
        coef = np.empty((cands.size, 3, rays))
        for k, rk in enumerate(cands):
            basis = _limb_basis(rho, rk, sigma)
            gram = basis.T @ basis + 1e-12 * np.eye(3)     # normal equations: 3 unknowns per ray
            c = np.linalg.solve(gram, basis.T @ prof)
            coef[k] = c
            res[k] = np.sum((basis @ c - prof) ** 2, axis=0)
        k = np.argmin(res, axis=0)
        idx = np.arange(rays)
        rim, limb = coef[k, 1, idx], coef[k, 2, idx]
        contrast = rim + limb
        total = float(np.sum(np.sort(res[k, idx])[: rays // 3]))   # the best third: sharp silhouettes
        if best is None or total < best[0]:
            # sub-pixel: a parabola through the residuals about the best candidate
            k0 = np.clip(k, 1, cands.size - 2)
            r0, r1, r2 = res[k0 - 1, idx], res[k0, idx], res[k0 + 1, idx]
            den = r0 - 2 * r1 + r2
            off = np.where(den > 0, 0.5 * (r0 - r2) / np.where(den > 0, den, 1.0), 0.0)
            edge = cands[k0] + np.clip(off, -1.0, 1.0) * 0.1
            rms = np.sqrt(res[k, idx] / rho.size) / np.maximum(np.abs(contrast), 1e-12)
            best = (total, RayEdges(edge, rim, limb, rms, phi, float(sigma)))
    return best[1]


def _tolerance(r: float) -> float:
    """Distance (px) from a circle of radius ``r`` within which an edge point lies on it."""
    return max(OUTLIER_FRACTION * r, 0.3)


def _consensus(ex: np.ndarray, ey: np.ndarray, contrast: np.ndarray, good: np.ndarray, r: float,
               trials: int = 400) -> np.ndarray:
    """The edge points on one circle: the circle through three of them that the most contrast
    agrees with (RANSAC, tolerance a fraction of the radius), refitted by least squares on its
    inliers. A shading terminator, a stand or a shadow lies off it."""
    idx = np.nonzero(good)[0]
    pts = np.stack([ex, ey], -1)
    tol = _tolerance(r)
    rng = np.random.default_rng(0)
    best, best_score = good & False, -1.0
    for _ in range(trials):
        a, b, c = pts[rng.choice(idx, 3, replace=False)]
        d = 2 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        if abs(d) < 1e-9:
            continue
        sa, sb, sc = a @ a, b @ b, c @ c
        ux = (sa * (b[1] - c[1]) + sb * (c[1] - a[1]) + sc * (a[1] - b[1])) / d
        uy = (sa * (c[0] - b[0]) + sb * (a[0] - c[0]) + sc * (b[0] - a[0])) / d
        rr = math.hypot(a[0] - ux, a[1] - uy)
        if not 0.8 * r < rr < 1.2 * r:
            continue
        inl = good & (np.abs(np.hypot(ex - ux, ey - uy) - rr) < 2.0 * tol)
        score = float(contrast[inl].sum())
        if score > best_score:
            best, best_score = inl, score
    keep = best
    for _ in range(3):   # least squares on the consensus, then its own inliers
        if keep.sum() < 3:
            return keep
        fx, fy, fr = fit_circle(pts[keep])
        keep = good & (np.abs(np.hypot(ex - fx, ey - fy) - fr) < tol)
    return keep


def _rim_lit(rays: RayEdges, contrast: np.ndarray, good: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rays whose rim stays lit up to the silhouette, weighted by that rim's brightness, when
    they cover :data:`MIN_ARC` of the outline; else every good ray, weighted by its contrast.

    Where the light falls on the far side of the ball, the shading fades to nothing at a
    terminator a pixel or more inside the silhouette, a fade the limb term fits as readily as the
    silhouette's own; only the rim's step marks the silhouette itself. A ball lit from the front
    has no step anywhere, but there the terminator is the silhouette."""
    # the rim's step counts in the ball's own sense (brighter than its ground, or darker): a
    # stand or a wall brighter than an unlit rim makes a step the other way
    rim = rays.rim * np.sign(np.median(rays.contrast[good]))
    top = float(np.percentile(rim[good], 90))
    lit = good & (rim > RIM_FRACTION * top)
    if not top > 0 or lit.sum() < MIN_ARC * rim.size:
        return contrast, good
    return rim, lit


def fit_outline(lum: np.ndarray, cx: float, cy: float, r: float,
                iterations: int = 2) -> FoundCircle | None:
    """The circle through the sharp, clear edges of the outline near (cx, cy, r), outliers dropped
    (tolerances relative to the radius); None when too little of the outline shows an edge."""
    rms = math.inf
    keep_share = 0.0
    for _ in range(iterations):
        rays = model_edges(lum, cx, cy, r)
        edge, phi = rays.edge, rays.phi
        contrast = np.abs(rays.contrast)   # a bright rim on a dark ground, or a dark ball on a brighter one
        good = np.isfinite(edge) & (contrast > 0)
        if good.sum() >= 3:
            good &= contrast > 0.2 * float(np.percentile(contrast[good], 90))
            good &= rays.rms < max(3.0 * float(np.percentile(rays.rms[good], 50)), 0.05)
        ex, ey = cx + edge * np.cos(phi), cy + edge * np.sin(phi)
        if good.sum() < MIN_ARC * edge.size:
            return None
        weight, lit = _rim_lit(rays, contrast, good)
        keep = _consensus(ex, ey, weight, lit, r)
        if keep.sum() < MIN_ARC * edge.size and lit is not good:   # too little of a lit rim: every edge
            keep = _consensus(ex, ey, contrast, good, r)
        if keep.sum() < MIN_ARC * edge.size:
            return None
        cx, cy, r = (float(v) for v in fit_circle(np.stack([ex[keep], ey[keep]], -1)))
        resid = np.hypot(ex[keep] - cx, ey[keep] - cy) - r
        rms = float(np.sqrt(np.mean(resid ** 2)))
        # the share of the outline seen on the circle: every clear edge, lit rim or limb, on it
        keep_share = float(np.mean(good & (np.abs(np.hypot(ex - cx, ey - cy) - r) < _tolerance(r))))
    return FoundCircle(cx, cy, r, keep_share, rms)


def find_ball(rgb: np.ndarray) -> FoundCircle:
    """The ball in a linear RGB photo (H, W, 3|4): votes, then the outline's fit (module docstring).

    Raises :class:`ImageInputError` when no circular outline is found."""
    lum = luminance(rgb)
    cx, cy, r, _ = vote_circle(lum)
    found = fit_outline(lum, cx, cy, r)
    smallest = 0.9 * MIN_RADIUS_FRACTION * min(lum.shape)
    if found is None or found.r < max(4.0, smallest):   # smaller than any ball searched: a screw, a spot
        raise ImageInputError(f"no sphere found (the best circular outline, centre ({cx:.0f}, {cy:.0f}), "
                              f"radius {r:.0f} px, shows a clear edge on less than {MIN_ARC:.0%} of "
                              "its length; give --circle X,Y,R or --mask)")
    return found
