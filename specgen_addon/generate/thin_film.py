"""Fit of the thin-film family to the photo: an interference film's angle-dependent colour from one
sphere photo, where the network's prior cannot place it.

The model is the corpus family :class:`~specgen_addon.corpus.families.thin_film.ThinFilm`: a GGX
lobe (roughness ``α``) whose Fresnel factor is the exact Airy reflectance ``R(θd, λ)`` of a film
(index ``η_f``, thickness ``d`` in nm) on a metal or dielectric substrate, plus, over a
dielectric, a Lambertian body ``ρ(λ)/π`` (added, not energy-coupled; fitted in the three-spectrum
basis of Mallett & Yuksel 2019, then given the spectral shape of a natural reflectance of the same
colour, Otsu et al. 2018, as the refinement's body: :mod:`specgen_addon.generate.refine.body`). Rendering is linear in the
BRDF, so under the photo's lighting (:class:`~specgen_addon.generate.refine.PhotoOperator`, the renderer's
own samples) the photo is

    photo[p, c] = Σ_j Σ_λ R(θd_j, λ) K_α[p, c, j, λ]  +  Σ_l ρ_l B[p, c, l],

with ``K_α`` the response of the lobe ``G_α(θh, θd, φd) = D G₂ / (4 cos θi cos θo)`` per unit
reflectance at table node ``θd_j`` and render wavelength ``λ``, and ``B`` that of a Lambertian body
per basis spectrum. The fit runs in three stages:

1. ``α``: for each roughness on a log grid, ``R`` free (smooth hats in θd × λ) and ``ρ ≥ 0`` are
   solved by least squares; the roughness with the smallest residual is kept;
2. ``(substrate, η_f, d)``: an exhaustive search of the Airy model on a grid (every measured metal
   and three dielectrics, η_f 1.2–2.6 in steps of 0.1, optical thickness η_f·d in 4 nm steps for
   d 0–1500 nm), ``ρ`` solved in closed form, in the design's reduced singular basis;
3. a finer local grid around the best candidate, and a non-negative body.

Everything is numpy (it runs inside a stock Blender); a 128² photo takes about 20–30 s on two cores,
twice that where the photo's blur is modelled (``blur_px``: a crop resampled from a camera photo).
Angles are radians, wavelengths nm, BRDF values sr⁻¹.
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from specgen_addon.corpus.families.thin_film import THICKNESS_RANGE_NM, ThinFilm, film_amplitudes, airy_reflectance
from specgen_addon.corpus.fresnel import cauchy_ior
from specgen_addon.corpus.material import ALPHA_RANGE, Conductor, Dielectric, Material
from specgen_addon.corpus.metals import METALS, metal_ior
from specgen_addon.corpus.microfacet import specular_geometry
from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.generate.refine import WARN_PSNR_DB
from specgen_addon.generate.refine.basis import CorrectionBasis, hat_matrix
from specgen_addon.generate.refine.blur import blur_image, blur_rows, rows_inside
from specgen_addon.generate.refine.body import natural_body
from specgen_addon.generate.refine.operator import PhotoOperator
from specgen_addon.render.photo_reproduction import Reproduction, reproduction
from specgen_addon.generate.refine.solve import nonneg_ridge
from specgen_addon.brdf.table import N_PHI_D, N_THETA_D, N_THETA_H, BRDFTable, grid_angles
from specgen_addon.generate.refine import render_under
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.render.photo_reproduction import checked_photo

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]

#: Roughness grid of stage 1 (log-spaced over the corpus's range up to 0.5).
ALPHA_GRID = np.geomspace(ALPHA_RANGE[0], 0.5, 14)
#: Film index grid of stage 2 (oils and soaps ≈ 1.33–1.5, oxides up to ≈ 2.4).
FILM_ETA_GRID = np.round(np.arange(1.2, 2.601, 0.1), 3)
#: Step of stage 2's grid in optical thickness η_f·d (nm): the phase 4π η_f d cos θ₁ / λ moves by
#: ≤ 0.13 rad per step across the visible range, whatever η_f.
OPTICAL_STEP_NM = 4.0
#: Singular vectors of the design kept by stage 2's reduction.
REDUCED_RANK = 320
#: Dielectric substrates tried (Cauchy A; B = 0.004 µm²): water-like, glass, dense glass/resin.
DIELECTRIC_CAUCHY_A = (1.32, 1.5, 1.7)
DIELECTRIC_CAUCHY_B_UM2 = 0.004
#: Pixels used by the fit (an even subset of the observed sphere, for speed).
MAX_FIT_PIXELS = 1500
#: Knots of stage 1's free reflectance: θd (radians) and λ (nm).
FREE_THETA_D_KNOTS = np.radians(np.arange(0.0, 90.1, 10.0))
SPECTRAL_KNOTS_NM = np.linspace(380.0, 780.0, 9)


@dataclass
class ThinFilmFit:
    """The fitted film: ``material`` (no body), the Lambertian body ``body_reflectance`` at
    ``body_wavelengths_nm`` (zeros over a metal), the fit's photo reproduction, and warnings (one
    sentence each: a photo the model does not explain)."""

    material: ThinFilm
    body_wavelengths_nm: np.ndarray
    body_reflectance: np.ndarray
    reproduction: Reproduction
    alpha_residuals: dict[float, float]
    warnings: list[str] = field(default_factory=list)
    blur_px: float = 0.0     # the photo's blur the fit modelled (Gaussian σ, pixels of the crop)

    def blur_note(self) -> str:
        """The modelled blur in words ("photo blur σ 1 px modelled"), or "" for a sharp photo; the
        CLI line and the panel summary both use it."""
        return f"photo blur σ {self.blur_px:g} px modelled" if self.blur_px > 0 else ""

    def _with_body(self, lobe: np.ndarray, cos_i: np.ndarray, cos_o: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The lobe's values (N, Λ) plus the body ``ρ(λ)/π`` where both directions are above the horizon."""
        above = (np.ravel(cos_i) > 0) & (np.ravel(cos_o) > 0)
        return lobe + above[:, None] * np.interp(w, self.body_wavelengths_nm, self.body_reflectance)[None] / np.pi

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        """``f_r(ωi, ωo, λ)`` in sr⁻¹, (N, Λ): the film's lobe plus the body ``ρ(λ)/π``."""
        w = np.asarray(wavelengths_nm, dtype=np.float64)
        return self._with_body(self.material.eval(wi, wo, w), np.asarray(wi)[:, 2], np.asarray(wo)[:, 2], w)

    def eval_hd(self, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray,
                wavelengths_nm: np.ndarray) -> np.ndarray:
        """``f_r`` at Rusinkiewicz angles (radians) → (N, Λ), as :meth:`eval`."""
        w = np.asarray(wavelengths_nm, dtype=np.float64)
        cos_i, cos_o, _, _ = Material._hd_cosines(theta_h, theta_d, phi_d)
        return self._with_body(self.material.eval_hd(theta_h, theta_d, phi_d, w), cos_i, cos_o, w)

    def table(self, wavelengths_nm: np.ndarray, progress: ProgressFn | None = None,
              cancel: CancelFn | None = None) -> BRDFTable:
        """The fitted BRDF on the MERL grid as a spectral table (sr⁻¹)."""
        w = np.asarray(wavelengths_nm, dtype=np.float64)
        meta = {"source": "specgen thin-film fit", "material": self.material.to_dict(),
                "description": self.material.kind, "fit_psnr_db": round(self.reproduction.psnr_db, 3),
                "fit_blur_px": self.blur_px}
        return BRDFTable.tabulate(lambda th, td, pd: self.eval_hd(th, td, pd, w), w, metadata=meta,
                                  progress=progress, cancel=cancel)


@functools.lru_cache(maxsize=1)
def _grid_cosines() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """cos θi, cos θo, cos θh at every MERL grid node (flat, read-only): the same for every α."""
    th, td, pd = np.meshgrid(*grid_angles(), indexing="ij")
    cosines = Material._hd_cosines(th, td, pd)[:3]
    for c in cosines:
        c.flags.writeable = False
    return cosines


def lobe_geometry(alpha: float) -> np.ndarray:
    """``G_α = D G₂ / (4 cos θi cos θo)`` (sr⁻¹) on the MERL grid nodes, (90, 90, 180)."""
    cos_i, cos_o, cos_h = _grid_cosines()
    return specular_geometry(cos_i, cos_o, cos_h, alpha).reshape(N_THETA_H, N_THETA_D, N_PHI_D)


def fit_pixels(op: PhotoOperator, max_pixels: int = MAX_FIT_PIXELS) -> np.ndarray:
    """Indices (into the operator's observed pixels) of an even subset of at most ``max_pixels``."""
    n = op.n_pixels
    return np.arange(n) if n <= max_pixels else np.unique(np.linspace(0, n - 1, max_pixels).round().astype(int))


def theta_d_response(op: PhotoOperator, geometry: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """``K[p, c, j, λ]``: linear-sRGB photo of the BRDF ``geometry · R`` per unit ``R(θd_j, λ)``.

    ``geometry`` (90, 90, 180) on the grid nodes; looked up trilinearly as the renderer looks up a
    table, so ``K`` reproduces the renderer's image of the tabulated film. ``pixels`` selects the
    operator's observed pixels; λ runs over ``op.render_wavelengths_nm``.
    """
    return spectral_to_rgb(op, theta_d_radiance(op, geometry, pixels))


def spectral_to_rgb(op: PhotoOperator, radiance: np.ndarray) -> np.ndarray:
    """(P, J, Λr) spectral responses → (P, 3, J, Λr) linear-sRGB photo responses (the operator's
    exposure and colour matching)."""
    return op.exposure * np.einsum("cw,pjw->pcjw", op.to_rgb, radiance, optimize=True)


def theta_d_radiance(op: PhotoOperator, geometry: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """The spectral part of :func:`theta_d_response`: (P, J, Λr) radiance per unit ``R(θd_j, λ)``,
    before the exposure and the colour matching (a third of its size: what the blur is applied to)."""
    n_sel = pixels.size
    compact = np.full(op.n_pixels, -1, dtype=np.int64)
    compact[pixels] = np.arange(n_sel)
    nw = op.render_wavelengths_nm.size
    acc = np.zeros((n_sel * N_THETA_D, nw))
    g = geometry.reshape(-1)
    for grp in op.groups:
        pix = compact[grp.pixel]
        keep = pix >= 0
        if not np.any(keep):
            continue
        pix = pix[keep]
        ih, jd, kp = (grp.ih[keep].astype(np.int64), grp.jd[keep].astype(np.int64),
                      grp.kp[keep].astype(np.int64))
        th, td, tp = grp.th[keep], grp.td[keep], grp.tp[keep]
        radiance = grp.weights[keep].astype(np.float64) @ grp.radiance_basis          # (S, Λr)
        kp1 = (kp + 1) % N_PHI_D
        for dj, wj in ((0, 1 - td), (1, td)):
            j = jd + dj
            w_sum = np.zeros(pix.size)
            for di, wi in ((0, 1 - th), (1, th)):
                base = ((ih + di) * N_THETA_D + j) * N_PHI_D
                w_sum += wi * ((1 - tp) * g[base + kp] + tp * g[base + kp1])
            w_sum *= wj
            # one scatter-add for every wavelength: entry (s, λ) → bin (pixel, θd node)·Λr + λ
            idx = pix * N_THETA_D + j
            lo, hi = int(idx.min()), int(idx.max()) + 1
            cells = ((idx - lo)[:, None] * nw + np.arange(nw)).ravel()
            acc[lo:hi] += np.bincount(cells, weights=(w_sum[:, None] * radiance).ravel(),
                                      minlength=(hi - lo) * nw).reshape(hi - lo, nw)
    return acc.reshape(n_sel, N_THETA_D, nw)


#: θd nodes blurred at a time by :func:`_lobe_rows` (bounds its image stack to ~30 MB at 128²).
_BLUR_NODES = 10


def _lobe_rows(op: PhotoOperator, geometry: np.ndarray, rows: np.ndarray, sigma_px: float) -> np.ndarray:
    """:func:`theta_d_response` at the observed pixels ``rows`` of the photo blurred by ``sigma_px``
    (every observed pixel's response is blurred, unobserved ones counting as 0), (P, 3, J, Λr)."""
    if sigma_px <= 0:
        return theta_d_response(op, geometry, rows)
    radiance = theta_d_radiance(op, geometry, np.arange(op.n_pixels))                 # (N, J, Λr)
    blur = blur_rows(op.shape, op.pixel_ids, sigma_px)
    out = np.empty((rows.size,) + radiance.shape[1:])
    for j in range(0, radiance.shape[1], _BLUR_NODES):
        out[:, j:j + _BLUR_NODES] = blur(np.ascontiguousarray(radiance[:, j:j + _BLUR_NODES]))[rows]
    return spectral_to_rgb(op, out)


def body_basis(wavelengths_nm: np.ndarray) -> np.ndarray:
    """(Λ, 3) reflectance basis of the body: Mallett & Yuksel 2019's blue, green and red spectra
    (smooth, summing to 1), so three coefficients in [0, 1] give a natural reflectance ≤ 1 — an
    RGB photo cannot constrain a finer body spectrum."""
    return CorrectionBasis().spectral_hats(wavelengths_nm)


def body_response(op: PhotoOperator, pixels: np.ndarray) -> np.ndarray:
    """``B[p, c, l]``: photo of the Lambertian body ``m_l(λ)/π`` per basis spectrum ``l``."""
    hats = body_basis(op.render_wavelengths_nm)                                         # (Λr, 3)
    per_band = op.lambert[pixels][:, :, None] * hats[None] / np.pi
    return op.exposure * np.einsum("cw,pwl->pcl", op.to_rgb, per_band, optimize=True)


def substrates(wavelengths_nm: np.ndarray) -> list[tuple[Dielectric | Conductor, np.ndarray]]:
    """Every candidate substrate with its (complex) index at ``wavelengths_nm``."""
    out: list[tuple[Dielectric | Conductor, np.ndarray]] = []
    for metal in METALS:
        eta, k = metal_ior(metal, wavelengths_nm)
        out.append((Conductor(metal), eta + 1j * k))
    for a in DIELECTRIC_CAUCHY_A:
        out.append((Dielectric(a, DIELECTRIC_CAUCHY_B_UM2), cauchy_ior(wavelengths_nm, a, DIELECTRIC_CAUCHY_B_UM2) + 0j))
    return out


class AiryThicknessSeries:
    """``airy_reflectance(cos θ, λ, η_f, d, n₂)`` of one film index on one substrate for many
    thicknesses ``d``, with everything that does not depend on ``d`` computed once.

    Per polarisation, with the interfaces' amplitudes ``a = r₀₁``, ``c = r₁₂`` and the phase
    ``δ = d κ``, ``κ = 4π η_f cos θ₁ / λ`` (real: a film of index > 1 seen from air),

        |a + c e^{iδ}|² / |1 + a c e^{iδ}|²
            = (|a|² + |c|² + 2 Re(ā c e^{iδ})) / (1 + |a c|² + 2 Re(a c e^{iδ})),

    so each thickness costs a cosine, a sine and real arithmetic instead of complex division.
    """

    def __init__(self, cos_theta: np.ndarray, wavelengths_nm: np.ndarray, film_eta: float,
                 substrate_n: np.ndarray):
        if not (np.isscalar(film_eta) and 1.0 < float(film_eta) < 4.0):
            raise SpecGenError(f"film index must be a number in (1, 4), got {film_eta!r}")
        c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
        lam = np.asarray(wavelengths_nm, dtype=np.float64)
        n1 = complex(float(film_eta))
        cos1, s, p = film_amplitudes(c, np.asarray(n1), np.asarray(substrate_n) + 0j)
        #: δ per nm of thickness, broadcast shape of cos θ and λ
        self.kappa = np.broadcast_to(np.real(4.0 * np.pi * float(film_eta) * cos1 / lam),
                                     np.broadcast_shapes(c.shape, lam.shape)).copy()
        self.terms = []
        for a, b in (s, p):
            u, v = np.conj(a) * b, a * b
            self.terms.append(tuple(np.broadcast_to(t, self.kappa.shape).copy() for t in (
                np.abs(a) ** 2 + np.abs(b) ** 2, 2 * u.real, -2 * u.imag,
                1.0 + np.abs(v) ** 2, 2 * v.real, -2 * v.imag)))

    def __call__(self, thickness_nm: np.ndarray) -> np.ndarray:
        """(N, *shape) reflectance for thicknesses (N,) in nm, clipped to [0, 1] as
        :func:`airy_reflectance`."""
        d = np.asarray(thickness_nm, dtype=np.float64).reshape((-1,) + (1,) * self.kappa.ndim)
        delta = d * self.kappa
        cos, sin = np.cos(delta), np.sin(delta)
        out = 0.0
        for num0, num_c, num_s, den0, den_c, den_s in self.terms:
            out = out + (num0 + num_c * cos + num_s * sin) / (den0 + den_c * cos + den_s * sin)
        return np.clip(0.5 * out, 0.0, 1.0)


class _ReducedDesign:
    """Residuals ``min_ρ ‖K R + B ρ − b‖²`` of many reflectance tables ``R``, in the reduced basis.

    ``[K B] = U S Vᵀ``; keeping the leading ``REDUCED_RANK`` vectors, ``‖b − K R − B ρ‖²`` is
    ``‖b⊥‖² + ‖Uᵀb − (SVᵀ)_K R − (SVᵀ)_B ρ‖²`` up to the truncation, and ``ρ`` (free, least
    squares) is projected out with the QR of ``(SVᵀ)_B``.
    """

    def __init__(self, k: np.ndarray, body: np.ndarray, b: np.ndarray):
        # S and V from the eigenvectors of the Gram matrix AᵀA = V S² Vᵀ (a symmetric
        # eigenproblem of the design's width, ~10× cheaper than the SVD of the tall design), and
        # Uᵀb = S⁻¹ Vᵀ Aᵀb; components under 10⁻¹² of the largest eigenvalue are dropped
        a = np.concatenate([k, body], axis=1)
        eig, v = np.linalg.eigh(a.T @ a)
        eig, v = eig[::-1], v[:, ::-1]                                  # largest first
        r = int(min(REDUCED_RANK, np.count_nonzero(eig > 1e-12 * max(eig[0], 1e-300))))
        sv = np.sqrt(eig[:r])
        coeff = sv[:, None] * v[:, :r].T                                # (r, JΛ + L)
        self.k = coeff[:, :k.shape[1]].T.copy()                         # (JΛ, r)
        self.q, _ = np.linalg.qr(coeff[:, k.shape[1]:])                 # (r, L)
        self.b = (v[:, :r].T @ (a.T @ b)) / sv

    def residuals(self, reflectance: np.ndarray, with_body: bool) -> np.ndarray:
        """(N,) residuals of reflectance tables (N, J, Λ)."""
        r = self.b[None, :] - reflectance.reshape(reflectance.shape[0], -1) @ self.k
        if with_body:
            r = r - (r @ self.q) @ self.q.T
        return np.einsum("nm,nm->n", r, r)


def fit_thin_film(photo: np.ndarray, lighting=None, clip_level: float | np.ndarray | None = 0.995,
                  progress: ProgressFn | None = None, cancel: CancelFn | None = None,
                  blur_px: Sequence[float] = (0.0,)) -> ThinFilmFit:
    """Fit the thin-film family (module docstring) to a sphere ``photo`` taken under ``lighting``.

    ``photo``: linear sRGB (S, S, 3) on the canonical sphere crop, as the refinement takes it;
    ``lighting``: :class:`~specgen_addon.photo.photo_lighting.InputLighting` (default canonical); pixels
    at or above ``clip_level`` (an 8-bit photo's full scale) are left out. ``blur_px``: the photo's
    blur widths (Gaussian σ, pixels of the crop) to choose among, with the roughness, by the stage-1
    residual, the fit modelling ``photo ≈ G_σ ∗ render`` as the refinement does
    (:mod:`specgen_addon.generate.refine.blur`): a resampled photo's highlight is spread over pixels, and
    fitted as sharp it reads as a rougher lobe. ``(0,)`` models no blur. Raises
    :class:`SpecGenError` on a malformed photo or blur and :class:`Cancelled` when ``cancel()`` is true.
    """
    photo = checked_photo(photo)
    lighting = lighting or InputLighting()
    sigmas = tuple(float(x) for x in np.atleast_1d(np.asarray(blur_px, dtype=np.float64)))
    if not sigmas or not all(np.isfinite(x) and 0.0 <= x <= 4.0 for x in sigmas):
        raise SpecGenError(f"blur_px must list blur widths in [0, 4] pixels, got {blur_px!r}")

    def step(fraction: float) -> None:
        if cancel is not None and cancel():
            raise Cancelled("thin-film fit cancelled")
        if progress is not None:
            progress(fraction)

    scene = lighting.scene(photo.shape[0])
    fit_wl = np.linspace(380.0, 780.0, 21)
    op = PhotoOperator(scene, fit_wl, lighting.image_exposure, cancel=cancel)
    wl = op.render_wavelengths_nm
    pixels = fit_pixels(op)
    observed = op.observe(photo)
    clipped = (np.zeros(op.n_pixels, bool) if clip_level is None
               else np.any(observed >= clip_level, axis=1))
    blurred = max(sigmas) > 0
    # rows fitted: the even subset, less clipped pixels and (with a blur) pixels whose blurred
    # neighbourhood reaches the unobserved rim or a clipped pixel, for the widest σ (one row set
    # for every σ, so that their residuals compare)
    keep = ~clipped[pixels]
    if blurred:
        keep &= rows_inside(op.shape, op.pixel_ids, max(sigmas), clipped)[pixels]
    if not np.any(keep):
        raise SpecGenError("every pixel of the photo is clipped: there is nothing to fit")
    rows = pixels[keep]
    b = observed[rows].reshape(-1)

    def blurred_rows(responses: np.ndarray, sigma: float) -> np.ndarray:
        """Responses of every observed pixel (N, ...) → the fitted rows of their image blurred by σ."""
        return blur_rows(op.shape, op.pixel_ids, sigma)(responses)[rows]

    body_all = body_response(op, np.arange(op.n_pixels)) if blurred else None
    bodies = {sg: (blurred_rows(body_all, sg) if blurred else body_response(op, rows)).reshape(-1, 3)
              for sg in sigmas}                                                    # (M, 3) per σ
    step(0.05)

    # Stage 1: roughness, with a free smooth reflectance R(θd, λ) and a free body; the best grid
    # roughness is then moved to the vertex of a parabola through its neighbours (in log α).
    td_nodes = grid_angles()[1]
    free_basis = np.einsum("ja,wl->jwal", hat_matrix(td_nodes, FREE_THETA_D_KNOTS),
                           hat_matrix(wl, SPECTRAL_KNOTS_NM)).reshape(N_THETA_D * wl.size, -1)
    scale = max(float(np.mean(b * b)), 1e-20)
    n_free = free_basis.shape[1]
    # the colour matching folded into the free basis: (J·Λr, 3·M), one product per roughness
    rgb_free_basis = op.exposure * np.concatenate(
        [np.tile(op.to_rgb[c], N_THETA_D)[:, None] * free_basis for c in range(3)], axis=1)

    def free_designs(alpha: float, widths: tuple[float, ...] = sigmas) -> dict[float, np.ndarray]:
        """Stage 1's design per σ of ``widths``: the lobe's photo in the free basis of R(θd, λ), then
        the body."""
        if not blurred:
            k = theta_d_response(op, lobe_geometry(alpha), rows).reshape(-1, N_THETA_D * wl.size)
            return {0.0: np.concatenate([k @ free_basis, bodies[0.0]], axis=1)}
        radiance = theta_d_radiance(op, lobe_geometry(alpha), np.arange(op.n_pixels))
        k_free = (radiance.reshape(op.n_pixels, -1) @ rgb_free_basis).reshape(op.n_pixels, 3, n_free)
        return {sg: np.concatenate([blurred_rows(k_free, sg).reshape(-1, n_free), bodies[sg]], axis=1)
                for sg in widths}

    def residual(design: np.ndarray) -> float:
        gram = design.T @ design + 1e-6 * scale * design.shape[0] * np.eye(design.shape[1])
        theta = nonneg_ridge(gram, design.T @ b)
        return float(np.sum((design @ theta - b) ** 2))

    # residuals per (σ, α); the best σ is then kept for the parabola in α
    res_grid: dict[tuple[float, float], float] = {}
    for n, alpha in enumerate(ALPHA_GRID):
        for sg, design in free_designs(float(alpha)).items():
            res_grid[(sg, float(alpha))] = residual(design)
        step(0.05 + 0.4 * (n + 1) / ALPHA_GRID.size)
    sigma, best_alpha = min(res_grid, key=res_grid.get)
    res_best = res_grid[(sigma, best_alpha)]
    alpha_res: dict[float, float] = {a: r for (sg, a), r in res_grid.items() if sg == sigma}
    i = int(np.flatnonzero(ALPHA_GRID == best_alpha)[0])
    if 0 < i < ALPHA_GRID.size - 1:
        x = np.log(ALPHA_GRID[i - 1:i + 2])
        y = np.array([alpha_res[float(a)] for a in ALPHA_GRID[i - 1:i + 2]])
        c2, c1, _ = np.polyfit(x, y, 2)
        if c2 > 0:
            vertex = float(np.exp(np.clip(-c1 / (2 * c2), x[0], x[2])))
            res = residual(free_designs(vertex, (sigma,))[sigma])
            alpha_res[vertex] = res
            if res < res_best:
                res_best, best_alpha = res, vertex
    body = bodies[sigma]
    k_best = _lobe_rows(op, lobe_geometry(best_alpha), rows, sigma).reshape(-1, N_THETA_D * wl.size)
    step(0.5)

    # Stage 2: the Airy model on a grid of (substrate, η_f, optical thickness η_f·d); the photo
    # and the design are reduced to the design's leading singular vectors (exact up to the
    # truncation: predictions lie in the design's column space), the body projected out there.
    reduced = _ReducedDesign(k_best, body, b)
    cos_nodes = np.cos(td_nodes)[:, None]
    subs = substrates(wl)

    def thickness_search(sub, n2: np.ndarray, eta_f: float) -> tuple[float, float]:
        """The best thickness (nm) of one film index on one substrate, and its residual."""
        ds = np.arange(0.0, eta_f * THICKNESS_RANGE_NM[1] + 1e-9, OPTICAL_STEP_NM) / eta_f
        res = reduced.residuals(AiryThicknessSeries(cos_nodes, wl, eta_f, n2)(ds), isinstance(sub, Dielectric))
        i = int(np.argmin(res))
        return float(res[i]), float(ds[i])

    best = (np.inf, None, None, 0.0, 0.0)
    # the film indices of a substrate on two threads (numpy's arithmetic and BLAS release the GIL);
    # the candidates are compared in the same order as one after the other
    with ThreadPoolExecutor(max_workers=2) as pool:
        for n, (sub, n2) in enumerate(subs):
            found = pool.map(lambda eta_f, sub=sub, n2=n2: thickness_search(sub, n2, float(eta_f)), FILM_ETA_GRID)
            for eta_f, (res, d) in zip(FILM_ETA_GRID, found):
                if res < best[0]:
                    best = (res, sub, n2, float(eta_f), d)
            step(0.5 + 0.4 * (n + 1) / len(subs))

    # Stage 3: a finer local grid around the best candidate (η_f ± 0.1, optical thickness ± one step).
    _, sub, n2, eta0, d0 = best
    with_body = isinstance(sub, Dielectric)
    etas, steps = np.meshgrid(np.clip(eta0 + np.arange(-0.1, 0.1001, 0.01), 1.01, 3.99),
                              np.arange(-OPTICAL_STEP_NM, OPTICAL_STEP_NM + 1e-9, OPTICAL_STEP_NM / 8),
                              indexing="ij")
    etas, ds = etas.ravel(), (eta0 * d0 + steps.ravel()) / etas.ravel()
    inside = (ds >= 0.0) & (ds <= THICKNESS_RANGE_NM[1])
    etas, ds = etas[inside], ds[inside]
    res = reduced.residuals(airy_reflectance(cos_nodes, wl, etas[:, None, None], ds[:, None, None], n2), with_body)
    eta_f, d = etas[int(np.argmin(res))], ds[int(np.argmin(res))]
    body_or_none = body if with_body else None
    film = ThinFilm(name="thin-film fit", split="test", alpha=float(best_alpha), film_eta=float(round(eta_f, 4)),
                    thickness_nm=float(round(d, 2)), substrate=sub)
    rho = np.zeros(3)
    if body_or_none is not None:
        pred = k_best @ airy_reflectance(cos_nodes, wl, film.film_eta, film.thickness_nm, n2).reshape(-1)
        rho = nonneg_ridge(body.T @ body + 1e-9 * np.eye(3), body.T @ (b - pred))
    reflectance = np.clip(body_basis(wl) @ np.clip(rho, 0.0, 1.0), 0.0, 1.0)
    natural = natural_body(reflectance / np.pi, wl) if np.any(rho > 0) else None
    if natural is not None:   # the body's spectral shape: a natural reflectance of its colour
        reflectance = np.clip(natural * np.pi, 0.0, 1.0)
    step(0.92)
    fit = ThinFilmFit(film, wl.copy(), reflectance,
                      Reproduction(float("nan"), None), alpha_res, blur_px=sigma)
    rendered = blur_image(render_under(fit.table(fit_wl), scene, lighting.image_exposure), sigma)
    fit.reproduction = reproduction(observed, op.observe(rendered))
    if fit.reproduction.psnr_db < WARN_PSNR_DB:
        fit.warnings.append(f"the thin-film model does not explain this photo: self-reproduction reaches only "
                            f"{fit.reproduction.psnr_db:.1f} dB (is the material a film? the network model "
                            f"may fit it better)")
    step(1.0)
    return fit
