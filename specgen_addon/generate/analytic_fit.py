"""Fit an analytic RGB BRDF to one sphere photo under known lighting (the photo-only baselines).

What a real alternative to SpecGen would do with the same single photograph: fit a Principled-style
analytic BRDF to the sphere under the input's lighting, then uplift its colours to spectra.

Model (:class:`AnalyticRGB`; the linear, Disney 2012 form of Blender's Principled BSDF, without its
energy coupling between layers)::

    f_r = d/π + G(α)·[F0·(1 − s⁵) + e·s⁵] + c·G(α_c)·[0.04 + 0.96·s⁵],   s = 1 − ω_o·h,

with ``G(α) = D G2 / (4 cos θi cos θo)`` the GGX lobe of :mod:`specgen_addon.corpus.microfacet`
(Walter et al. 2007, Heitz 2014 height-correlated Smith), Schlick's Fresnel split into its ``F0``
and grazing parts, ``d`` the diffuse colour, ``F0`` the specular colour at normal incidence, ``e``
the (white) grazing weight of the specular lobe (1 for Schlick) and ``c`` the weight of a clear
coat of index 1.5 (F0 = 0.04) with its own roughness ``α_c``. Principled's base colour, metallic
and specular map onto it as ``d = base·(1 − metallic)`` and ``F0 = mix(0.08·specular, base,
metallic)``; fitting ``d`` and ``F0`` independently covers every such combination.

Fit (:func:`fit_photo`). Rendering is linear in the BRDF, so for fixed roughnesses the photo is a
linear function of ``θ = (d_R, d_G, d_B, F0_R, F0_G, F0_B, e, c)``: one render of each scalar
basis lobe (unit Lambert, ``G(α)(1 − s⁵)``, ``G(α)s⁵``, the coat lobe) under the prepared scene
gives each column, channel by channel (each channel lit by its own channel of the lighting). The
colours come from non-negative least squares (all three channels at once, so the grazing and coat
weights stay white) for every pair on a roughness grid (coat sharper than the base, or no coat);
the pair with the smallest residual wins and each roughness is then refined by a golden-section
search in ``log α`` between its grid neighbours. numpy only (the NNLS is the active-set solver of
:mod:`specgen_addon.generate.refine.solve`), so it runs inside a stock Blender.

Spectral BRDF (:class:`AnalyticSpectral`): the same lobes with ``d`` and ``F0`` replaced by
reflectance spectra (uplifted by :func:`specgen_addon.evaluation.photo_fit.uplift_fit`).

Used by the photo-only baselines (:mod:`specgen_addon.evaluation.photo_fit`) and by the network's
canonical input for a photo under a known light (:mod:`specgen_addon.generate.canonical_input`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.corpus.microfacet import specular_geometry
from specgen_addon.generate.refine.operator import RIM_COS
from specgen_addon.generate.refine.solve import nonneg_ridge

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]

#: Base-lobe roughness grid (GGX α, log-spaced; one step is a factor of 10^(1/10) ≈ 1.26).
ALPHA_GRID = tuple(float(a) for a in np.geomspace(0.01, 1.0, 21))
#: Clear-coat roughness grid (only pairs with α_c < α are tried, plus "no coat").
COAT_ALPHA_GRID = tuple(float(a) for a in np.geomspace(0.01, 0.3, 15))
#: Normal-incidence reflectance of the clear coat (index 1.5).
COAT_F0 = 0.04
#: Names of the fitted linear coefficients, in design-matrix order.
COEFFICIENTS = ("diffuse_r", "diffuse_g", "diffuse_b", "f0_r", "f0_g", "f0_b", "edge", "coat")


def observed_pixels(scene) -> np.ndarray:
    """Flat mask (H·W,) of the photo pixels a fit or a self-reproduction score uses: the sphere
    facing the camera, off its grazing rim (cos θo ≥ :data:`specgen_addon.generate.refine.operator.RIM_COS`,
    the refinement's own rule: the outermost ring mixes sphere and background in a photo)."""
    normals = scene.geometry.normals.reshape(-1, 3)
    return scene.geometry.mask.reshape(-1) & (normals @ scene.camera_dir >= RIM_COS)


def _above(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    return (wi[:, 2] > 0) & (wo[:, 2] > 0)


def _lobe(wi: np.ndarray, wo: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """``G(α)`` (sr⁻¹) and Schlick's ``s⁵ = (1 − ω_o·h)⁵`` at direction pairs (N, 3)."""
    h = wi + wo
    norm = np.linalg.norm(h, axis=1, keepdims=True)
    h = np.divide(h, norm, out=np.zeros_like(h), where=norm > 0)
    g = specular_geometry(wi[:, 2], wo[:, 2], h[:, 2], alpha)
    s5 = (1.0 - np.clip(np.sum(wo * h, axis=1), 0.0, 1.0)) ** 5
    return g, s5


def basis_lobes(wi: np.ndarray, wo: np.ndarray, alpha: float, coat_alpha: float | None) -> np.ndarray:
    """The four scalar basis BRDFs (N, 4) in sr⁻¹: Lambert 1/π, ``G(α)(1 − s⁵)``, ``G(α)s⁵`` and
    the coat lobe ``G(α_c)(0.04 + 0.96 s⁵)`` (zero without a coat)."""
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    g, s5 = _lobe(wi, wo, alpha)
    out = np.zeros((wi.shape[0], 4))
    out[:, 0] = _above(wi, wo) / np.pi
    out[:, 1] = g * (1.0 - s5)
    out[:, 2] = g * s5
    if coat_alpha is not None:
        gc, s5c = _lobe(wi, wo, coat_alpha)
        out[:, 3] = gc * (COAT_F0 + (1.0 - COAT_F0) * s5c)
    return out


@dataclass(frozen=True)
class AnalyticRGB:
    """The fitted RGB BRDF (module docstring): linear-sRGB colours, roughnesses as GGX α."""

    diffuse: tuple[float, float, float]
    f0: tuple[float, float, float]
    alpha: float
    edge: float = 1.0
    coat: float = 0.0
    coat_alpha: float | None = None

    is_spectral = False  # render with eval_rgb (input_image's convention)

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """``f_r`` (N, 3) in sr⁻¹, local frame with the normal on +z."""
        b = basis_lobes(wi, wo, self.alpha, self.coat_alpha if self.coat > 0 else None)
        return (b[:, :1] * np.asarray(self.diffuse) + b[:, 1:2] * np.asarray(self.f0)
                + (self.edge * b[:, 2:3] + self.coat * b[:, 3:4]))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> AnalyticRGB:
        return cls(tuple(d["diffuse"]), tuple(d["f0"]), float(d["alpha"]), float(d["edge"]),
                   float(d["coat"]), None if d.get("coat_alpha") is None else float(d["coat_alpha"]))


@dataclass(frozen=True)
class AnalyticSpectral:
    """:class:`AnalyticRGB` with spectral colours: ``diffuse`` and ``f0`` are reflectances on
    ``wavelengths_nm`` (linear interpolation in between, ends held)."""

    wavelengths_nm: np.ndarray
    diffuse: np.ndarray
    f0: np.ndarray
    alpha: float
    edge: float = 1.0
    coat: float = 0.0
    coat_alpha: float | None = None

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        """``f_r`` (N, Λ) in sr⁻¹ at ``wavelengths_nm`` (nm)."""
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        d = np.interp(wl, self.wavelengths_nm, self.diffuse)
        f0 = np.interp(wl, self.wavelengths_nm, self.f0)
        b = basis_lobes(wi, wo, self.alpha, self.coat_alpha if self.coat > 0 else None)
        return b[:, :1] * d + b[:, 1:2] * f0 + (self.edge * b[:, 2:3] + self.coat * b[:, 3:4])


@dataclass
class PhotoFit:
    """Result of :func:`fit_photo`: the BRDF, its relative RMS residual over the fitted pixels, the
    residual of every grid pair tried (``(α, α_c or None) -> residual``) and the render count."""

    brdf: AnalyticRGB
    residual: float
    grid: dict[tuple[float, float | None], float] = field(default_factory=dict)
    renders: int = 0
    pixels: int = 0

    def summary(self) -> str:
        b = self.brdf
        coat = f", coat {b.coat:.3f} (α_c {b.coat_alpha:.3f})" if b.coat > 0 and b.coat_alpha else ""
        return (f"α {b.alpha:.3f}, diffuse ({', '.join(f'{x:.3f}' for x in b.diffuse)}), "
                f"F0 ({', '.join(f'{x:.3f}' for x in b.f0)}), edge {b.edge:.3f}{coat}; "
                f"relative RMS residual {self.residual:.4f} over {self.pixels} pixels")


class _ScalarLobe:
    """One scalar basis BRDF, for :meth:`specgen_addon.render.Scene.render_rgb` (same value in R, G, B)."""

    def __init__(self, fn: Callable[[np.ndarray, np.ndarray], np.ndarray]):
        self.fn = fn

    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.repeat(self.fn(wi, wo)[:, None], 3, axis=1)


def nnls(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``argmin ‖a x − b‖²`` subject to ``x ≥ 0`` (a: (M, K), b: (M,)), on the normal equations.

    Columns are scaled to unit norm first and a ridge of 1e-12 (relative) keeps the Gram matrix
    positive definite where two basis renders are nearly collinear.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    norms = np.linalg.norm(a, axis=0)
    scale = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 0.0)
    an = a * scale
    gram = an.T @ an
    gram[np.diag_indices_from(gram)] += 1e-12 + (norms == 0)
    return nonneg_ridge(gram, an.T @ b) * scale


class _Design:
    """Basis renders of the photo's pixels under one prepared scene, cached by roughness."""

    def __init__(self, scene, exposure: float, keep: np.ndarray, cancel: CancelFn | None,
                 max_edge: float | None = None):
        self.scene = scene
        self.max_edge = max_edge  # the grazing weight's upper bound (None: unbounded)
        self.exposure = float(exposure)
        self.keep = keep
        self.cancel = cancel
        self.renders = 0
        self._cache: dict[tuple[str, float], np.ndarray] = {}

    def _render(self, key: tuple[str, float], fn: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
        if key not in self._cache:
            if self.cancel is not None and self.cancel():
                raise Cancelled("photo fit cancelled")
            img = self.scene.render_rgb(_ScalarLobe(fn)).rgb
            self._cache[key] = img.reshape(-1, 3)[self.keep] * self.exposure   # (P, 3)
            self.renders += 1
        return self._cache[key]

    def lambert(self) -> np.ndarray:
        return self._render(("lambert", 0.0), lambda wi, wo: basis_lobes(wi, wo, 1.0, None)[:, 0])

    def specular(self, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        body = self._render(("f0", alpha), lambda wi, wo: basis_lobes(wi, wo, alpha, None)[:, 1])
        edge = self._render(("edge", alpha), lambda wi, wo: basis_lobes(wi, wo, alpha, None)[:, 2])
        return body, edge

    def coat(self, alpha: float) -> np.ndarray:
        return self._render(("coat", alpha), lambda wi, wo: basis_lobes(wi, wo, 1.0, alpha)[:, 3])

    def matrix(self, alpha: float, coat_alpha: float | None) -> np.ndarray:
        """Design matrix (3P, 8): rows pixel-major (R, G, B of each pixel), columns :data:`COEFFICIENTS`."""
        lam = self.lambert()
        body, edge = self.specular(alpha)
        p = lam.shape[0]
        a = np.zeros((p, 3, 8))
        for ch in range(3):
            a[:, ch, ch] = lam[:, ch]
            a[:, ch, 3 + ch] = body[:, ch]
        a[:, :, 6] = edge
        if coat_alpha is not None:
            a[:, :, 7] = self.coat(coat_alpha)
        return a.reshape(3 * p, 8)


def _solve(design: _Design, b: np.ndarray, alpha: float, coat_alpha: float | None) -> tuple[np.ndarray, float]:
    a = design.matrix(alpha, coat_alpha)
    theta = nnls(a, b)
    if design.max_edge is not None and theta[6] > design.max_edge:
        # the problem is convex, so with the bound violated the optimum lies on it: e = max_edge
        free = [k for k in range(a.shape[1]) if k != 6]
        theta = np.insert(nnls(a[:, free], b - design.max_edge * a[:, 6]), 6, design.max_edge)
    r = a @ theta - b
    return theta, float(r @ r)


def _golden(f: Callable[[float], float], lo: float, hi: float, steps: int) -> float:
    """Minimiser of ``f`` on [lo, hi] by ``steps`` golden-section iterations (ends kept in play)."""
    g = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(steps):
        if fc <= fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    return c if fc <= fd else d


def fit_photo(photo: np.ndarray, scene, exposure: float, *, alphas: tuple[float, ...] = ALPHA_GRID,
              coat_alphas: tuple[float, ...] = COAT_ALPHA_GRID, refine_steps: int = 6, rounds: int = 2,
              clip_level: float | np.ndarray | None = None, exclude: np.ndarray | None = None,
              max_edge: float | None = None, progress: ProgressFn | None = None,
              cancel: CancelFn | None = None) -> PhotoFit:
    """Fit :class:`AnalyticRGB` to a sphere ``photo`` rendered under a prepared renderer ``scene``.

    Parameters
    ----------
    photo
        Linear sRGB (H, W, 3), the scene's image size (e.g. :func:`specgen_addon.photo.sphere_image.render_input`).
    scene
        :class:`specgen_addon.render.Scene` of the photo (geometry, lights, environment): e.g.
        :func:`specgen_addon.photo.sphere_image._scene` for the canonical input or
        :meth:`specgen_addon.photo.photo_lighting.InputLighting.scene` for another lighting.
    exposure
        Photo = exposure × rendered radiance (:data:`specgen_addon.photo.sphere_image.EXPOSURE`).
    alphas, coat_alphas
        Roughness grids (GGX α) of the base lobe and of the coat (``()``: no coat).
    refine_steps, rounds
        Golden-section iterations per roughness, and rounds of alternating base/coat searches,
        after the grid search (``refine_steps = 0``: grid only).
    clip_level
        Pixels with a channel at or above this value are left out (clipped PNG/JPEG); None: keep all.
        The silhouette's grazing rim is always left out (:func:`observed_pixels`).
    exclude
        (H, W) bool: further pixels left out (e.g. those that saw a saturated source pixel).
    max_edge
        Upper bound of the specular lobe's grazing weight ``e`` (1: at most Schlick's Fresnel).
        A photo rarely sees the grazing angles, and an unbounded ``e`` can grow without limit
        there, which matters wherever the fit is rendered under another light.
    """
    photo = np.asarray(photo, dtype=np.float64)
    h, w = scene.geometry.shape
    if photo.shape != (h, w, 3):
        raise SpecGenError(f"photo has shape {photo.shape}; the scene renders {(h, w, 3)}")
    if not np.all(np.isfinite(photo)):
        raise SpecGenError("photo holds NaN or Inf values")
    if not (np.isfinite(exposure) and exposure > 0):
        raise SpecGenError(f"exposure must be positive, got {exposure}")
    keep = observed_pixels(scene)
    rows = photo.reshape(-1, 3)
    if clip_level is not None:
        keep &= ~np.any(rows >= clip_level, axis=1)
    if exclude is not None:
        keep &= ~np.asarray(exclude, dtype=bool).reshape(-1)
    if keep.sum() < 16:
        raise SpecGenError(f"only {int(keep.sum())} usable sphere pixels in the photo; cannot fit")
    b = rows[keep].reshape(-1)
    energy = float(b @ b)
    if not energy > 0:
        raise SpecGenError("the photo is black on the sphere: there is nothing to fit")
    design = _Design(scene, exposure, keep, cancel, max_edge)
    pairs = [(a, None) for a in alphas] + [(a, c) for a in alphas for c in coat_alphas if c < a]
    grid: dict[tuple[float, float | None], float] = {}
    for i, (a, c) in enumerate(pairs):
        grid[(a, c)] = _solve(design, b, a, c)[1]
        if progress is not None:
            progress(0.8 * (i + 1) / len(pairs))
    alpha, coat_alpha = min(grid, key=grid.get)
    best = grid[(alpha, coat_alpha)]
    # Coordinate descent: golden-section search in log α, then in log α_c, each within one grid
    # step of the current value (the coat kept sharper than the base), ``rounds`` times; a step is
    # kept only if it lowers the residual.
    step_a = float(np.log(alphas[1] / alphas[0])) if len(alphas) > 1 else 0.0
    step_c = float(np.log(coat_alphas[1] / coat_alphas[0])) if len(coat_alphas) > 1 else 0.0
    for r in range(rounds if refine_steps > 0 else 0):
        la = np.log(alpha)
        lo = max(la - step_a, np.log(coat_alpha) if coat_alpha is not None else -np.inf, np.log(alphas[0]))
        hi = min(la + step_a, np.log(alphas[-1]))
        if hi > lo:
            cand = float(np.exp(_golden(lambda x, c=coat_alpha: _solve(design, b, float(np.exp(x)), c)[1],
                                        lo, hi, refine_steps)))
            res = _solve(design, b, cand, coat_alpha)[1]
            if res < best:
                alpha, best = cand, res
        if coat_alpha is not None:
            lc = np.log(coat_alpha)
            lo, hi = max(lc - step_c, np.log(coat_alphas[0])), min(lc + step_c, np.log(alpha))
            if hi > lo:
                cand = float(np.exp(_golden(lambda x, a=alpha: _solve(design, b, a, float(np.exp(x)))[1],
                                            lo, hi, refine_steps)))
                res = _solve(design, b, alpha, cand)[1]
                if res < best:
                    coat_alpha, best = cand, res
        if progress is not None:
            progress(0.8 + 0.2 * (r + 1) / rounds)
    theta, res = _solve(design, b, alpha, coat_alpha)
    if progress is not None:
        progress(1.0)
    has_coat = coat_alpha is not None and theta[7] > 0
    brdf = AnalyticRGB(tuple(float(x) for x in theta[:3]), tuple(float(x) for x in theta[3:6]), float(alpha),
                       float(theta[6]), float(theta[7]) if has_coat else 0.0,
                       float(coat_alpha) if has_coat else None)
    return PhotoFit(brdf, float(np.sqrt(res / energy)), grid, design.renders, int(keep.sum()))
