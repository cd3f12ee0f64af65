"""Photo-consistent refinement: analysis by synthesis after the network (:func:`refine_brdf`).

The network's table ``f`` is a prior. The photo is the measurement. Rendering is linear in the
BRDF (:mod:`.operator`), so a small correction (:mod:`.basis`) — a spectral × angular tint of the
specular lobe, a separate tint of the diffuse body and an added Lambertian term — enters the photo
linearly and is found by regularised non-negative least squares (:mod:`.solve`):

    minimise ‖A θ − photo‖² / σ² + ρ ‖θ − θ0‖²_D + smoothness,   θ ≥ 0,

with ``θ0`` the identity (the network's own table), ``σ`` one percent of the photo's level and the
prior weighted by each coefficient's own data sensitivity ``D`` (so a coefficient the photo barely
sees stays with the network). Clipped pixels (PNG/JPEG at full scale) are left out of the fit.
The photo's blur (lens, pixel area, the crop's resampling) is modelled on the rendered side,
``photo ≈ G_σ ∗ Aθ``, with σ chosen by the fit (:mod:`.blur`).

The diffuse body's spectral shape then comes from a natural-reflectance basis (:mod:`.body`): the
first solve finds the body's colour, the body is replaced by the Otsu 2018 reflectance of that
colour, and the coefficients are solved again around it (the lobe's design is shared, so the second
solve costs a few milliseconds). Metals keep the network's spectra.

The result is checked by rendering it with the reference renderer under the same lighting:
self-reproduction PSNR and ΔE2000 (:mod:`.report`). If the refined table reproduces the photo worse
than the network's did, the network's table is returned unchanged. Everything is numpy: it runs
inside a stock Blender (no torch, scipy or colour-science needed; ΔE2000 is reported where
colour-science is installed).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from specgen_addon.brdf.table import BRDFTable
from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.generate.refine.basis import CorrectionBasis
from specgen_addon.generate.refine.blur import (
    BLUR_CANDIDATES_PX,
    blur_image,
    blur_rows,
    embed_rows,
    gather_rows,
    gaussian_blur_stack,
    rows_inside,
    search_blur,
)
from specgen_addon.generate.refine.body import (
    BODY_PRIORS,
    blended_body,
    blind_share,
    has_separate_body,
    natural_body,
)
from specgen_addon.generate.refine.discrepancy import difference_variance, discrepancy_scale, twin_scene
from specgen_addon.generate.refine.holdout import block_folds, holdout_error, holdout_errors
from specgen_addon.generate.refine.lighting_check import any_light_lambertian_db, bright_residual_share, lighting_warning
from specgen_addon.generate.refine.operator import PhotoOperator, render_grid
from specgen_addon.generate.refine.solve import difference_operator, nonneg_ridge
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.render.photo_reproduction import Reproduction, checked_photo, photo_scale, reproduction
from specgen_addon.render.renderer import Scene
from specgen_addon.render.sampling import diffuse_floor

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]

#: Self-reproduction below this (dB), and well below a Lambertian under any lighting
#: (:func:`~specgen_addon.generate.refine.lighting_check.lighting_suspect`), means the lighting
#: does not explain the photo: warn.
WARN_PSNR_DB = 30.0
#: Self-reproduction (dB) below which the smoothness is relaxed to :data:`RELAXED_SMOOTH` and the
#: better-reproducing of the two corrections is kept (the photo target is 40 dB).
RELAX_BELOW_DB = 42.0
RELAXED_SMOOTH = 0.01
#: The relaxed fit replaces the smooth one only if it reproduces the photo at least this much better
#: (dB): a small gain is as likely the operator's sampling error or the photo's resampling fitted as
#: the material (docs/refinement.md).
RELAX_MIN_GAIN_DB = 0.0
#: The relaxed fit is tried only if, fitted to half of the sphere's pixels, it predicts the other half
#: better than the smooth fit does (:mod:`.holdout`): a looser fit that gains only on the pixels it
#: was fitted to is fitting their noise (chosen on fresh validation photos:
#: +1.05 dB of truth on average, no photo worse; docs/refinement.md).
RELAX_HOLDOUT = True
#: Which smoothness the relaxed fit loosens: ``"both"`` axes, or ``"theta_h"`` only (a lobe may be
#: sharp in θh; along θd, Fresnel and masking change slowly, and a fit free there amplified a
#: highlight 8× at a θd that only the dim environment lights: docs/refinement.md).
RELAX_AXES = "both"
RELAX_AXES_CHOICES = ("both", "theta_h")
#: The lobe's correction is kept only if it predicts held-out pixels better than the network's own
#: lobe (with the body's tint and the added Lambertian fitted either way, :mod:`.holdout`).
LOBE_HOLDOUT = False
#: The fit stops at this multiple of the renderer's own sampling-error variance (the discrepancy
#: principle, :mod:`.discrepancy`). Off by default: on the validation photos it lowered
#: the fit of brightness and colour where the sampling error is large (docs/refinement.md).
FIT_FLOOR: float | None = None
#: How the photo's blur is searched among :data:`.blur.BLUR_CANDIDATES_PX` (:func:`.blur.search_blur`):
#: ``"walk"`` from the middle candidate towards the smaller residual until it rises (3–4 solves of
#: the six; the same σ as ``"all"`` on every shared photo and test, docs/refinement.md), ``"all"``
#: every candidate.
BLUR_SEARCH = "walk"
#: Photo values at or above this fraction of the maximum 8-bit level count as clipped.
CLIP_LEVEL = 0.995
#: Under distant lights alone (no map, no ambient) a pixel sees the material at θd = ½ · the angle
#: between the light and the camera, whatever its normal. Lights whose θd lie closer together than
#: this (degrees; under half the smallest interval between the correction's θd knots, 12°) show the
#: photo one θd only: it constrains one mix of the two θd knots around it and none of their
#: difference, so the relaxed fit keeps the θd smoothness there (:func:`theta_d_seen`).
THETA_D_SEEN_SPAN_DEG = 5.0


@dataclass(frozen=True)
class RefineOptions:
    """Knobs of the refinement (defaults are the shipped behaviour).

    ``noise`` is σ as a fraction of the photo's level; ``prior`` the pull towards the network
    (relative to each coefficient's data weight); ``smooth`` the smoothness between neighbouring
    knots (3: chosen on the validation split, docs/refinement.md), ``smooth_theta_d`` that between θd
    knots where it differs (``None``: ``smooth``); ``body_prior`` the spectral
    shape of the diffuse body: ``"otsu2018"`` (a natural reflectance of the photo's body colour,
    :mod:`.body`), ``"network"`` (the network's own body spectrum, tinted), ``"blend"`` (the two
    mixed, ``body_blend`` being the network's share) or ``"tails"`` (Otsu 2018's where the eye sees,
    the network's where its :func:`.body.visibility` is below ``body_visibility``); ``additive`` adds
    the angular term ``u`` (:func:`apply_correction`), which gives a shape to near-Lambertian
    tables that the multiplicative lobe correction cannot scale; ``clip_level`` marks saturated
    pixels of an 8/16-bit photo (values at or above ``clip_level`` × ``full_scale``): they are left
    out of the fit, and renders are clipped at ``full_scale`` like the photo before they are scored
    (``None``: a linear EXR photo, nothing is clipped). ``fit_floor`` τ: the fit leaves at least τ × the renderer's own sampling-error variance
    as its residual (measured per photo, :mod:`.discrepancy`), and keeps the network's table where that
    already does; ``None`` fits as closely as the prior allows (the behaviour of earlier
    versions). ``relax_below_db``: below this self-reproduction the smoothness is relaxed and the better
    fit kept, if it reproduces the photo at least ``relax_min_gain_db`` better; with ``relax_holdout`` it
    is tried only if it also predicts held-out pixels better (:mod:`.holdout`); ``relax_axes``: the
    smoothness it loosens (``"both"``, or ``"theta_h"`` only; ``"both"`` loosens θd only where the
    lighting shows more than one θd, :func:`theta_d_seen`). ``lobe_holdout``: the lobe's
    correction is kept only where it predicts held-out pixels better than the network's lobe.
    ``smooth_weight``: ``"pair"`` weights each difference between neighbouring knots by
    the data weight of the two knots it ties (at least the block's median), so that knots the photo
    sees strongly move together (a sharp highlight's); ``"block"`` uses the block's median for all
    (the earlier default). ``prior_floor`` adds the same pull to every coefficient, as a fraction of the largest
    data weight: combinations of coefficients the photo barely constrains stay with the network.
    ``score_holdout``: also report how well the kept setting, fitted to one half of the sphere's
    pixels, predicts the other (:attr:`RefineResult.holdout_db`, two more solves): a score of the
    starting table as a prior that, unlike self-reproduction, does not grow with the fit's freedom.
    """

    basis: CorrectionBasis = field(default_factory=CorrectionBasis)
    noise: float = 0.01
    prior: float = 1e-5
    prior_floor: float = 1e-11
    smooth_weight: str = "pair"
    smooth: float = 3.0
    smooth_theta_d: float | None = None
    relax_below_db: float = RELAX_BELOW_DB
    relax_min_gain_db: float = RELAX_MIN_GAIN_DB
    relax_holdout: bool = RELAX_HOLDOUT
    relax_axes: str = RELAX_AXES
    lobe_holdout: bool = LOBE_HOLDOUT
    fit_floor: float | None = FIT_FLOOR
    body_prior: str = "otsu2018"
    body_blend: float = 0.5
    body_visibility: float = 0.3
    additive: bool = True
    clip_level: float | None = CLIP_LEVEL
    #: the photo's full scale per channel (R, G, B): 1, or the white balance's gains where they were
    #: applied to an 8/16-bit photo (its camera clipped before the balance)
    full_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    energy_check: bool = True
    blur_px: float | None = None
    score_holdout: bool = False
    #: (S, S) bool, pixels of the crop left out of the fit (saturated in the source photo in any
    #: format: :attr:`specgen_addon.photo.sphere_image.SphereCrop.saturated`); None: none beyond clip_level
    exclude: np.ndarray | None = field(default=None, compare=False, hash=False)

    def __post_init__(self) -> None:
        if self.blur_px is not None and not (np.isfinite(self.blur_px) and 0.0 <= self.blur_px <= 4.0):
            raise SpecGenError(f"blur_px must be None or a number of pixels in [0, 4], got {self.blur_px!r}")
        if not (np.isfinite(self.relax_min_gain_db) and self.relax_min_gain_db >= 0):
            raise SpecGenError(f"relax_min_gain_db must be a non-negative number of dB, got {self.relax_min_gain_db!r}")
        if self.relax_axes not in RELAX_AXES_CHOICES:
            raise SpecGenError(f"relax_axes must be one of {', '.join(RELAX_AXES_CHOICES)}, got {self.relax_axes!r}")
        if self.smooth_theta_d is not None and not (np.isfinite(self.smooth_theta_d) and self.smooth_theta_d >= 0):
            raise SpecGenError(f"smooth_theta_d must be None or a non-negative number, got {self.smooth_theta_d!r}")
        if self.smooth_weight not in ("pair", "block"):
            raise SpecGenError(f"smooth_weight must be 'pair' or 'block', got {self.smooth_weight!r}")
        if self.fit_floor is not None and not (np.isfinite(self.fit_floor) and self.fit_floor >= 0):
            raise SpecGenError(f"fit_floor must be None or a non-negative number, got {self.fit_floor!r}")
        if not (np.isfinite(self.body_blend) and 0.0 <= self.body_blend <= 1.0):
            raise SpecGenError(f"body_blend must be a share in [0, 1], got {self.body_blend!r}")
        if not (np.isfinite(self.body_visibility) and 0.0 < self.body_visibility <= 1.0):
            raise SpecGenError(f"body_visibility must be in (0, 1], got {self.body_visibility!r}")
        if self.body_prior not in BODY_PRIORS:
            raise SpecGenError(f"unknown body prior {self.body_prior!r} (choose from {', '.join(BODY_PRIORS)})")

    @property
    def theta_d_smooth(self) -> float:
        """The smoothness between neighbouring θd knots: ``smooth_theta_d``, or ``smooth`` where unset."""
        return self.smooth if self.smooth_theta_d is None else self.smooth_theta_d


@dataclass
class RefineResult:
    """The refined table, how well it and the network reproduce the photo, and what was found."""

    table: BRDFTable
    before: Reproduction
    after: Reproduction
    coefficients: dict
    seconds: float
    clipped_fraction: float
    warnings: list[str] = field(default_factory=list)
    rendered: np.ndarray | None = None       # (H, W, 3) refined render under the input lighting
    improved: bool = True
    blur_px: float = 0.0                     # the photo's blur the fit modelled (Gaussian σ, px)
    sampling_floor_db: float | None = None   # the operator's own sampling error as a PSNR (dB)
    prior_scale: float = 0.0                 # the discrepancy principle's factor on its pull
    within_noise: bool = False               # the network's lobe met the photo to that error: kept
    relaxed_gain_db: float | None = None     # self-reproduction gain of the relaxed fit, where one was tried
    relaxed: bool = False                    # the relaxed fit was kept
    relaxed_holdout_db: float | None = None  # held-out pixels: relaxed fit's gain over the smooth one (dB)
    lobe_holdout_db: float | None = None     # held-out pixels: the lobe's correction's gain over the network's lobe (dB)
    lobe_kept: bool = False                  # the network's lobe was kept (brightness and colour fitted)
    holdout_db: float | None = None          # score_holdout: held-out pixels predicted by the kept setting
                                             # fitted to the others, as a PSNR (dB, the photo's level)
    any_light_db: float | None = None        # a Lambertian under the best distant lighting of any kind
                                             # (lighting_check): what the lighting is judged against
    bright_share: float | None = None        # the squared residual's share on the brightest pixels (lighting_check)

    def summary(self) -> str:
        blur = f" (photo blur σ {self.blur_px:g} px modelled)" if self.blur_px > 0 else ""
        if self.within_noise and self.improved:
            return (f"self-reproduction {self.before.text()} → {self.after.text()}{blur}: brightness and colour "
                    f"fitted, the network's lobe kept (the rest is within the renderer's sampling error, "
                    f"{self.sampling_floor_db:.1f} dB) in {self.seconds:.1f} s")
        if self.lobe_kept and self.improved:
            return (f"self-reproduction {self.before.text()} → {self.after.text()}{blur}: brightness and colour "
                    f"fitted, the network's lobe kept (a corrected lobe predicted unseen pixels no better) "
                    f"in {self.seconds:.1f} s")
        return (f"self-reproduction {self.before.text()} → {self.after.text()}{blur} "
                f"in {self.seconds:.1f} s")


def diffuse_floor_of(table: BRDFTable) -> np.ndarray:
    """The renderer's control-variate floor ``c(λ)`` of a table (its Lambertian part), (Λ,)."""
    return diffuse_floor(lambda wi, wo: table.eval(wi, wo))


def render_under(table: BRDFTable, scene, exposure: float) -> np.ndarray:
    """Photo (H, W, 3) of ``table`` under a prepared scene: the reference renderer, as the input,
    integrated on :func:`.operator.render_grid` of the table's bands."""
    res = scene.render_spectral(table, render_grid(table.wavelengths))
    return np.clip(res.rgb, 0.0, None) * exposure


def _smoothness(basis: CorrectionBasis) -> tuple[np.ndarray, np.ndarray]:
    """Differences between neighbouring θh and θd knots (not across λ: a tint may be saturated),
    and the axis (0: θh, 1: θd) of each."""
    shape = basis.shape
    rows = [difference_operator(shape, ax) for ax in (0, 1)]
    return np.concatenate(rows, axis=0), np.repeat([0, 1], [r.shape[0] for r in rows])


def theta_d_seen(scene: Scene) -> bool:
    """Whether a scene's lighting shows the material over a range of θd (degrees): always under an
    environment (a map or an ambient term lights every direction); under distant lights alone only
    if their θd = ½ · angle(light, camera) span at least :data:`THETA_D_SEEN_SPAN_DEG`. The hold-out
    check cannot tell: every pixel shares the θd."""
    if scene.environment is not None:
        return True
    cos = [float(np.clip(np.dot(li.unit_direction(), scene.camera_dir), -1.0, 1.0)) for li in scene.lights]
    theta_d = [0.5 * math.degrees(math.acos(c)) for c in cos]
    return max(theta_d) - min(theta_d) >= THETA_D_SEEN_SPAN_DEG


def refine_brdf(table: BRDFTable, photo: np.ndarray, lighting=None, options: RefineOptions = RefineOptions(),
                progress: ProgressFn | None = None, cancel: CancelFn | None = None) -> RefineResult:
    """Refine the network's spectral ``table`` so that, under ``lighting``, it reproduces ``photo``.

    Parameters
    ----------
    table
        Spectral BRDF table (sr⁻¹) from the network; not modified.
    photo
        The input photo as the network saw it before any gain: linear sRGB (S, S, 3) on the
        canonical sphere crop (:func:`specgen_addon.photo.sphere_image.load_sphere_image`).
    lighting
        :class:`~specgen_addon.photo.photo_lighting.InputLighting` (default: canonical).
    options
        :class:`RefineOptions`.
    progress, cancel
        ``progress(fraction)``; ``cancel()`` returning True raises :class:`Cancelled`.
    """
    t0 = time.perf_counter()
    if not isinstance(table, BRDFTable) or not table.is_spectral:
        raise SpecGenError("refinement needs a spectral BRDFTable (the network's output), "
                           f"got {type(table).__name__ if not isinstance(table, BRDFTable) else 'an RGB table'}")
    lighting = lighting or InputLighting()
    photo = checked_photo(photo)

    def report(lo: float, hi: float) -> ProgressFn | None:
        return None if progress is None else (lambda f: progress(lo + (hi - lo) * min(max(f, 0.0), 1.0)))

    def check_cancel() -> None:
        if cancel is not None and cancel():
            raise Cancelled("refinement cancelled")

    wl = table.wavelengths
    basis = options.basis
    scene = lighting.scene(photo.shape[0])
    exposure = lighting.image_exposure
    op = PhotoOperator(scene, wl, exposure, progress=report(0.0, 0.1), cancel=cancel)
    b = op.observe(photo)                                           # (P, 3)
    warnings: list[str] = []
    level = photo_scale(b)
    clipped = np.zeros(b.shape[0], dtype=bool)
    full_scale = np.asarray(options.full_scale, np.float64)
    if options.clip_level is not None:
        clipped = np.any(b >= options.clip_level * full_scale, axis=1)
    if options.exclude is not None:
        clipped |= op.observe(np.repeat(np.asarray(options.exclude, np.float64)[..., None], 3, -1))[:, 0] > 0.5
    clipped_fraction = float(clipped.mean()) if clipped.size else 0.0
    if clipped_fraction > 0.25:
        warnings.append(f"{100 * clipped_fraction:.0f}% of the sphere is clipped at full scale; "
                        f"those pixels carry no brightness information")
    if not np.any(b > 0):
        warnings.append("the photo is black: there is nothing to reproduce")

    # the network's table under the input's lighting, with the operator's samples and with
    # independent ones: the first is the "before" check, the two together measure the operator's
    # sampling error (:mod:`.discrepancy`); rendered on a side thread while the designs are built
    with ThreadPoolExecutor(max_workers=2) as pool:
        before_job = pool.submit(render_under, table, scene, exposure)
        twin_job = (pool.submit(render_under, table, twin_scene(scene), exposure)
                    if options.fit_floor is not None else None)
        floor = diffuse_floor_of(table)
        s_hats = basis.spectral_hats(wl)
        a_lobe = op.lobe_design(table.values, floor, basis, progress=report(0.1, 0.6), cancel=cancel)
        check_cancel()
        a_lamb = op.lambert_design(np.full(wl.size, 1.0 / np.pi), s_hats)  # z: added Lambertian
        n_lobe, nl = basis.n_lobe, s_hats.shape[1]
        a_lobe = a_lobe.reshape(b.shape[0], 3, -1)
        if options.additive:   # u: an added angular term h_a(θh) g_b(θd) s_l(λ), for near-Lambertian tables
            a_add = op.added_design(basis, progress=report(0.6, 0.65), cancel=cancel)
            a_lobe = np.concatenate([a_lobe, a_add.reshape(b.shape[0], 3, -1)], axis=2)
        before_raw = before_job.result()
        twin_raw = None if twin_job is None else twin_job.result()
        sigma, a_lobe_fit, a_lamb_fit, searched = _photo_blur(op, a_lobe, a_lamb, op.lambert_design(floor, s_hats), b,
                                                    clipped, n_lobe, nl, level, basis, options, check_cancel,
                                                    None if twin_raw is None else before_raw - twin_raw)
        blur = blur_rows(op.shape, op.pixel_ids, sigma)
        keep = rows_inside(op.shape, op.pixel_ids, sigma, clipped)
        floor_residual = sampling_floor = None
        if twin_raw is not None:        # the residual the true material would leave (discrepancy principle)
            n2 = difference_variance(op.observe(blur_image(before_raw - twin_raw, sigma))[keep])
            floor_residual = options.fit_floor * n2
            sampling_floor = 10.0 * math.log10(level ** 2 / n2) if n2 > 0 else math.inf
            check_cancel()
        scales: list[float] = []

        def design_for(body: np.ndarray) -> np.ndarray:
            a_body = blur(op.lambert_design(body, s_hats))                # y: tint of the body
            return np.concatenate([a_lobe_fit, a_body, a_lamb_fit], axis=2)[keep]  # (P, 3, K)

        photo_rows = b[keep]

        sigma2 = (options.noise * level) ** 2
        last: list = [None, None]                                  # the last design solved, its data term

        def design_terms(design: np.ndarray) -> _DataTerms:
            """The data term of a design made by ``design_for`` (every design solved here is: they
            differ in the body's columns only): that of the last one solved where it is the same
            (the relaxed fit), else it with only the body's columns made again (the natural body
            replacing the network's)."""
            if last[0] is not design:
                body_cols = slice(a_lobe.shape[2], a_lobe.shape[2] + nl)
                if last[0] is not None:
                    terms = _with_columns(last[1], design, photo_rows, body_cols)
                elif searched is not None:        # the blur search's, moved to these rows
                    terms = _with_columns(_moved_rows(searched, keep, design, b, a_lobe_fit, a_lamb_fit, nl),
                                          design, photo_rows, body_cols)
                else:
                    terms = _data_terms(design, photo_rows, sigma2)
                last[:] = [design, terms]
            return last[1]

        def solve(design: np.ndarray, opts: RefineOptions = options) -> np.ndarray:
            theta, scale = _solve_correction(design, photo_rows, n_lobe, nl, level, basis, opts, floor_residual,
                                             design_terms(design))
            scales.append(scale)
            return theta

        shared: dict[int, tuple[np.ndarray, np.ndarray, _DataTerms]] = {}

        def data_terms(d: np.ndarray, y: np.ndarray) -> _DataTerms:
            """The data term of rows ``d``, ``y``, made once while those arrays live: the settings a
            hold-out compares are fitted to the same fold's rows (:func:`.holdout_errors`)."""
            kept = shared.get(id(d))
            if kept is None or kept[0] is not d or kept[1] is not y:
                kept = shared[id(d)] = (d, y, _data_terms(d, y, sigma2))
            return kept[2]

        def fit_rows(opts: RefineOptions, lobe_kept: bool = False):
            """A solver of the correction for a subset of the fitted rows (:func:`.holdout_error`)."""
            if lobe_kept:
                return lambda d, y: _normal_equations(d, y, n_lobe, nl, level, basis, opts,
                                                      data_terms(d, y)).solve(_PULL_MAX)
            return lambda d, y: _solve_correction(d, y, n_lobe, nl, level, basis, opts, floor_residual,
                                                  data_terms(d, y))[0]

        def holdout_db(design: np.ndarray, candidate, reference) -> float:
            """How much better (dB) the fit ``candidate`` predicts held-out pixels than ``reference``."""
            folds = block_folds(op.shape, op.pixel_ids[keep])
            ref_err, cand_err = holdout_errors(design, photo_rows, folds, [reference, candidate])
            shared.clear()
            if not (np.isfinite(ref_err) and np.isfinite(cand_err)) or cand_err <= 0 or ref_err <= 0:
                return -math.inf
            return 10.0 * math.log10(ref_err / cand_err)

        n_all = a_lobe.shape[2]                                           # lobe x, then added u

        def split(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
            """θ → (lobe x, added u or None, body tint y, Lambertian z)."""
            return (theta[:n_lobe], theta[n_lobe:n_all] if options.additive else None,
                    theta[n_all:n_all + nl], theta[n_all + nl:])

        def corrected(theta: np.ndarray, body: np.ndarray) -> BRDFTable:
            x, u, yb, zl = split(theta)
            return apply_correction(table, floor, x, yb, zl, basis, body=body, added=u)

        body = floor
        design = design_for(body)
        theta = solve(design)
        if options.body_prior != "network" and has_separate_body(table.values, floor, wl):
            _, _, yb, zl = split(theta)
            fitted = floor * (s_hats @ yb) + (s_hats @ zl) / np.pi     # the network's body, colour fitted
            natural = natural_body(fitted, wl)
            if natural is not None:
                if options.body_prior == "otsu2018":
                    body = natural
                else:
                    share = (options.body_blend if options.body_prior == "blend"
                             else blind_share(wl, options.body_visibility))
                    body = blended_body(natural, fitted, share)
                design = design_for(body)
                theta = solve(design)
        check_cancel()
        if progress is not None:
            progress(0.65)

        within_noise = not np.isfinite(scales[-1])     # the network's lobe already meets the photo
        lobe_holdout = None
        if options.lobe_holdout and not within_noise:
            # does the lobe's correction predict pixels it was not fitted to better than the
            # network's own lobe (brightness and colour fitted either way)?
            lobe_holdout = holdout_db(design, fit_rows(options), fit_rows(options, lobe_kept=True))
            if lobe_holdout <= 0:
                theta = fit_rows(options, lobe_kept=True)(design, photo_rows)
            check_cancel()
        lobe_kept = lobe_holdout is not None and lobe_holdout <= 0
        refined = corrected(theta, body)
        if options.energy_check:
            warnings.extend(_energy_warnings(table, refined))
        check_cancel()
        after_raw = render_under(refined, scene, exposure)
        if progress is not None:
            progress(0.9)

        def clip(img: np.ndarray) -> np.ndarray:   # an 8/16-bit photo: the camera clipped at full scale
            return img if options.clip_level is None else np.minimum(img, full_scale)

        def as_photographed(img: np.ndarray) -> np.ndarray:   # blurred by the lens and the crop, then clipped
            return clip(blur_image(img, sigma))

        before_img = as_photographed(before_raw)
        after_img = as_photographed(after_raw)
        m_before = reproduction(b, op.observe(before_img))
        m_after = reproduction(b, op.observe(after_img))
        relaxed_gain, relaxed_kept, relaxed_holdout = None, False, None
        relax_theta_d = options.relax_axes == "both" and theta_d_seen(scene)   # else θd is not in the photo
        relaxed_opts = replace(options, smooth=RELAXED_SMOOTH,
                               smooth_theta_d=RELAXED_SMOOTH if relax_theta_d else options.theta_d_smooth)
        try_relax = m_after.psnr_db < options.relax_below_db and options.smooth > RELAXED_SMOOTH and not lobe_kept
        if try_relax and options.relax_holdout:
            relaxed_holdout = holdout_db(design, fit_rows(relaxed_opts), fit_rows(options))
            check_cancel()
        if try_relax and (relaxed_holdout is None or relaxed_holdout > 0):
            # the smooth correction does not explain the photo (and, with the hold-out check, the
            # relaxed one predicts pixels it was not fitted to better): relax the smoothness
            theta_r = solve(design, relaxed_opts)
            relaxed = corrected(theta_r, body)
            relaxed_img = as_photographed(render_under(relaxed, scene, exposure))
            m_relaxed = reproduction(b, op.observe(relaxed_img))
            relaxed_gain = m_relaxed.psnr_db - m_after.psnr_db
            if relaxed_gain > 0 and relaxed_gain >= options.relax_min_gain_db:
                theta, refined, after_img, m_after = theta_r, relaxed, relaxed_img, m_relaxed
                relaxed_kept = True
        heldout = None
        if options.score_holdout:   # the kept setting, fitted to one half of the pixels, on the other
            err = holdout_error(design, photo_rows, block_folds(op.shape, op.pixel_ids[keep]),
                                fit_rows(relaxed_opts if relaxed_kept else options, lobe_kept))
            heldout = 10.0 * math.log10(level ** 2 / err) if 0 < err < math.inf else None
            check_cancel()
        x, u, yb, zl = split(theta)
        if progress is not None:
            progress(0.98)
        improved = m_after.psnr_db >= m_before.psnr_db
        if not improved:
            warnings.append(f"refinement did not improve on the network ({m_after.psnr_db:.1f} dB vs "
                            f"{m_before.psnr_db:.1f} dB); the network's table is kept")
            refined, after_img, m_after = table, before_img, m_before
        normals = scene.geometry.normals.reshape(-1, 3)[op.pixel_ids]
        any_light = any_light_lambertian_db(b, normals, ~clipped, None if options.clip_level is None else full_scale,
                                            level)
        bright_share = bright_residual_share(b, op.observe(after_img))
        lighting_note = lighting_warning(m_after.psnr_db, any_light, bright_share, WARN_PSNR_DB,
                                        studio=lighting.is_canonical)
        if lighting_note is not None:
            warnings.append(lighting_note)
        coeffs = {"lobe": x.reshape(basis.shape).tolist(), "body_tint": yb.tolist(),
                  "added": None if u is None else u.reshape(basis.shape).tolist(),
                  "lambert": zl.tolist(), "floor": floor.tolist(), "body": body.tolist(),
                  "body_prior": options.body_prior if body is not floor else "network"}
        meta = dict(refined.metadata)
        if improved:
            meta.update({"refined": True, "refine_lighting": lighting.label,
                         "refine_psnr_db": round(m_after.psnr_db, 3),
                         "refine_delta_e2000": None if m_after.delta_e2000 is None else round(m_after.delta_e2000, 4)})
            refined.metadata = meta
        if progress is not None:
            progress(1.0)
        return RefineResult(refined, m_before, m_after, coeffs, time.perf_counter() - t0, clipped_fraction,
                            warnings, after_img, improved, sigma, sampling_floor,
                            float(max(scales)), within_noise, relaxed_gain, relaxed_kept and improved,
                            relaxed_holdout, lobe_holdout, lobe_kept and improved, heldout, any_light,
                            bright_share)


def _photo_blur(op: PhotoOperator, a_lobe: np.ndarray, a_lamb: np.ndarray, a_body: np.ndarray,
                b: np.ndarray, clipped: np.ndarray, n_lobe: int, nl: int, level: float,
                basis: CorrectionBasis, options: RefineOptions, check_cancel: Callable[[], None],
                twin_difference: np.ndarray | None = None
                ) -> tuple[float, np.ndarray, np.ndarray, tuple[np.ndarray, _DataTerms] | None]:
    """The photo's blur σ (px) and the lobe and Lambertian designs blurred by it: σ is
    ``options.blur_px``, or the candidate of :data:`.blur.BLUR_CANDIDATES_PX` whose first solve
    leaves the smallest mean squared residual on the rows every candidate keeps (searched as
    :data:`BLUR_SEARCH` says: :func:`.blur.search_blur`). With a search, also the rows it
    compared on (a mask over the operator's rows) and the chosen candidate's data term there
    (:func:`_moved_rows` reuses it); else None.

    With ``twin_difference`` (H, W, 3: the network's table rendered with the operator's samples
    minus with independent ones, :mod:`.discrepancy`) each candidate's residual is first reduced
    by the operator's sampling-error variance after that blur: blurring averages the operator's
    noise away, which must not count as explaining the photo (a sharp photo that shares no
    samples with the operator would otherwise be fitted as a blurred one)."""
    if options.blur_px is not None:
        blur = blur_rows(op.shape, op.pixel_ids, float(options.blur_px))
        return float(options.blur_px), blur(a_lobe), blur(a_lamb), None
    common = rows_inside(op.shape, op.pixel_ids, max(BLUR_CANDIDATES_PX), clipped)
    if not np.any(common):              # nothing every candidate sees (a clipped photo): no blur
        return 0.0, a_lobe, a_lamb, None
    n_lobe_cols, n_body = a_lobe.shape[2], a_body.shape[2]
    # every candidate blurs one stack of all the design's columns (in float32: half the memory
    # traffic); its rows are read with the fitted (common) rows first, in their own order, so that
    # each fit reads a contiguous block
    columns = (a_lobe, a_body, a_lamb)
    image = embed_rows(op.shape, op.pixel_ids, np.concatenate(columns, axis=2), dtype=np.float32)
    order = np.concatenate([np.flatnonzero(common), np.flatnonzero(~common)])
    n_common = int(common.sum())
    b_common = b[common]
    best: list = [math.inf, 0.0, None, None]                     # residual, σ, rows, their data term

    sigma2 = (options.noise * level) ** 2

    def residual_at(k: int) -> float:
        sigma = BLUR_CANDIDATES_PX[k]
        if sigma > 0:       # kept in float32: the blurred stack's values, widened exactly where used
            blurred = gaussian_blur_stack(image, sigma, dtype=np.float32)
            rows = gather_rows(blurred, op.pixel_ids[order]).reshape(order.size, 3, -1)
            del blurred
        else:                                                    # unblurred: the design as it is
            rows = np.concatenate(columns, axis=2)[order]
        design = rows[:n_common]
        terms = _data_terms_by_chunks(design, b_common, sigma2)
        eq = _normal_equations(design, b_common, n_lobe, nl, level, basis, options, terms)
        residual = eq.residual(eq.solve(0.0))
        if twin_difference is not None:
            residual -= difference_variance(op.observe(blur_image(twin_difference, sigma))[common])
        if residual < best[0]:
            best[:] = [residual, sigma, rows, terms]
        check_cancel()
        return residual

    search_blur(residual_at, len(BLUR_CANDIDATES_PX), BLUR_SEARCH)
    sigma, rows = best[1], best[2]
    in_order = np.empty_like(rows)
    in_order[order] = rows                                       # back to the operator's rows
    return sigma, in_order[:, :, :n_lobe_cols], in_order[:, :, n_lobe_cols + n_body:], (common, best[3])


#: The discrepancy pull's largest factor: the lobe's coefficients are then the network's to ~10⁻⁶.
_PULL_MAX = 1e14


@dataclass
class _DataTerms:
    """The data term ``‖A θ − y‖² / σ²`` of one design's rows: shared by every setting fitted to them."""

    gram: np.ndarray          # AᵀA / σ²
    rhs: np.ndarray           # Aᵀy / σ²
    yy: float                 # yᵀy / σ²
    n_obs: int
    sigma2: float


def _data_terms(design: np.ndarray, photo: np.ndarray, sigma2: float) -> _DataTerms:
    """:class:`_DataTerms` of the rows ``design`` (P, 3, K) and ``photo`` (P, 3)."""
    a = design.reshape(-1, design.shape[-1])
    y = photo.reshape(-1)
    return _DataTerms(a.T @ a / sigma2, a.T @ y / sigma2, float(y @ y) / sigma2, y.size, sigma2)


#: Rows per chunk of :func:`_data_terms_by_chunks` (a few MB of float64 at a time).
_CHUNK_ROWS = 2048


def _data_terms_by_chunks(design: np.ndarray, photo: np.ndarray, sigma2: float) -> _DataTerms:
    """:func:`_data_terms` of float32 or float64 rows, widened to float64 a chunk of rows at a
    time: the same sums (to float rounding) without a float64 copy of the whole design."""
    a = design.reshape(-1, design.shape[-1])
    y = photo.reshape(-1)
    n = 3 * _CHUNK_ROWS
    gram = np.zeros((a.shape[1], a.shape[1]))
    rhs = np.zeros(a.shape[1])
    chunk = np.empty((min(n, a.shape[0]), a.shape[1]))
    for start in range(0, a.shape[0], n):
        c = chunk[:min(n, a.shape[0] - start)]
        c[...] = a[start:start + c.shape[0]]
        gram += c.T @ c
        rhs += c.T @ y[start:start + c.shape[0]]
    return _DataTerms(gram / sigma2, rhs / sigma2, float(y @ y) / sigma2, y.size, sigma2)


def _moved_rows(searched: tuple[np.ndarray, _DataTerms], keep: np.ndarray, design: np.ndarray, photo: np.ndarray,
                a_lobe: np.ndarray, a_lamb: np.ndarray, nl: int) -> _DataTerms:
    """The blur search's data term of its rows (mask ``common`` over the operator's rows) made that
    of the rows ``keep``, whose design is ``design``: the rows only ``keep`` has added, those only
    ``common`` has taken away. Its body columns are not those of ``design`` (the search blurred
    another body): :func:`_with_columns` makes them again."""
    common, terms = searched
    added, taken = keep & ~common, common & ~keep
    plus = _data_terms(design[added[keep]], photo[added], terms.sigma2)
    body = np.zeros((int(taken.sum()), 3, nl))
    minus = _data_terms(np.concatenate([a_lobe[taken], body, a_lamb[taken]], axis=2), photo[taken], terms.sigma2)
    return _DataTerms(terms.gram + plus.gram - minus.gram, terms.rhs + plus.rhs - minus.rhs,
                      terms.yy + plus.yy - minus.yy, terms.n_obs + plus.n_obs - minus.n_obs, terms.sigma2)


def _with_columns(terms: _DataTerms, design: np.ndarray, photo: np.ndarray, cols: slice) -> _DataTerms:
    """:func:`_data_terms` of ``design``, which differs from the design of ``terms`` in the
    columns ``cols`` only (the body's tint under another body spectrum): those rows and columns
    of the Gram matrix and right-hand side are made again, the rest kept."""
    a = design.reshape(-1, design.shape[-1])
    y = photo.reshape(-1)
    gram, rhs = terms.gram.copy(), terms.rhs.copy()
    cross = a.T @ a[:, cols] / terms.sigma2
    gram[:, cols] = cross
    gram[cols, :] = cross.T
    rhs[cols] = a[:, cols].T @ y / terms.sigma2
    return _DataTerms(gram, rhs, terms.yy, terms.n_obs, terms.sigma2)


@dataclass
class _NormalEquations:
    """The data term ``‖A θ − y‖² / σ²`` and the regularisers of one design, built once, so that
    the prior's strength can be searched without touching the design again."""

    gram: np.ndarray          # AᵀA / σ²
    rhs: np.ndarray           # Aᵀy / σ²
    yy: float                 # yᵀy / σ²
    n_obs: int
    sigma2: float
    ridge: np.ndarray         # the prior's per-coefficient pull
    pull: np.ndarray          # the pull the discrepancy principle scales (added at ``scale`` × it)
    smooth: np.ndarray        # the smoothness term's Gram matrix
    theta0: np.ndarray

    def solve(self, scale: float = 0.0) -> np.ndarray:
        """θ with ``scale`` × :attr:`pull` added to the prior's pull (0: the plain fit)."""
        ridge = self.ridge + scale * self.pull
        gram = self.gram + self.smooth
        gram[np.diag_indices_from(gram)] += ridge
        return nonneg_ridge(gram, self.rhs + ridge * self.theta0)

    def residual(self, theta: np.ndarray) -> float:
        """Mean squared residual ``mean((A θ − y)²)`` in photo units."""
        sq = float(theta @ self.gram @ theta - 2.0 * theta @ self.rhs + self.yy)
        return max(sq, 0.0) * self.sigma2 / self.n_obs


def _normal_equations(design: np.ndarray, photo: np.ndarray, n_lobe: int, nl: int, level: float,
                      basis: CorrectionBasis, options: RefineOptions,
                      data: _DataTerms | None = None) -> _NormalEquations:
    """The regularised least squares of the module docstring for the observed pixels' design
    (P, 3, K) and photo (P, 3), coefficients θ = (lobe x, added u, body tint y, Lambertian z);
    ``data``: their data term made already (:func:`_data_terms`, the same noise level)."""
    n_add = design.shape[2] - n_lobe - 2 * nl                    # the added angular term (0 or n_lobe)
    theta0 = np.concatenate([np.ones(n_lobe), np.zeros(n_add), np.ones(nl), np.zeros(nl)])
    sigma2 = (options.noise * level) ** 2
    if data is None or data.sigma2 != sigma2:
        data = _data_terms(design, photo, sigma2)
    gram, rhs = data.gram, data.rhs
    # prior: each coefficient pulled to θ0 in proportion to its own data weight (plus a floor, so
    # coefficients the photo cannot see stay exactly at the network's value)
    diag = np.diag(gram).copy()
    ridge = options.prior * diag + options.prior_floor * max(diag.max(), 1.0)
    # smoothness between neighbouring θh and θd knots of the lobe correction (and of the added
    # term), scaled by its own block's median data weight, or per difference by the data weight of
    # the two knots it ties ("pair", at least that median); and the pull the discrepancy principle
    # strengthens: the same within each of these blocks (the least-seen coefficients give way
    # first), none on the body's tint and the added Lambertian (brightness, colour stay free)
    smooth_rows, axis = _smoothness(basis)
    strength = np.where(axis == 0, options.smooth, options.theta_d_smooth)
    lo, hi = np.argmax(smooth_rows < 0, axis=1), np.argmax(smooth_rows > 0, axis=1)
    smooth = np.zeros_like(gram)
    pull = np.zeros_like(diag)
    blocks = [slice(0, n_lobe)] + ([slice(n_lobe, n_lobe + n_add)] if n_add else [])
    for block in blocks:
        d = np.maximum(diag[block], 1e-12)
        median = float(np.median(d))
        w = np.sqrt(d[lo] * d[hi]) if options.smooth_weight == "pair" else np.zeros(lo.size)
        w = strength * np.maximum(w, median)
        smooth[block, block] += smooth_rows.T @ (w[:, None] * smooth_rows)
        pull[block] = 1e-8 * median
    return _NormalEquations(gram, rhs, data.yy, data.n_obs, sigma2, ridge, pull, smooth, theta0)


def _solve_correction(design: np.ndarray, photo: np.ndarray, n_lobe: int, nl: int, level: float,
                      basis: CorrectionBasis, options: RefineOptions,
                      floor_residual: float | None = None, data: _DataTerms | None = None) -> tuple[np.ndarray, float]:
    """θ and the factor on the prior's pull that it was solved with.

    Without ``floor_residual`` the factor is 0. With it (the photo's expected misfit, mean squared,
    :mod:`.discrepancy`), the pull on the lobe's and the added term's coefficients is strengthened
    until the fit leaves at least that residual; the factor is ``inf`` where the network's lobe, with
    only the body's tint and the added Lambertian fitted (brightness and colour), already does."""
    eq = _normal_equations(design, photo, n_lobe, nl, level, basis, options, data)
    if floor_residual is None:
        return eq.solve(0.0), 0.0
    scale = discrepancy_scale(lambda s: eq.residual(eq.solve(s)), floor_residual, hi=_PULL_MAX)
    return eq.solve(min(scale, _PULL_MAX)), scale


def apply_correction(table: BRDFTable, floor: np.ndarray, x: np.ndarray, body_tint: np.ndarray,
                     lambert: np.ndarray, basis: CorrectionBasis, body: np.ndarray | None = None,
                     added: np.ndarray | None = None) -> BRDFTable:
    """``f' = c' + (f − c) Φ`` on the grid (see :mod:`.basis`), clipped at 0; a new table.

    Plus, with ``added`` (Na, Nb, L), the non-negative angular term ``Σ u_abl h_a(θh) g_b(θd) s_l(λ)``
    (sr⁻¹), smooth across knots and pulled to zero like the rest.
    ``c' = body(λ) Σ y s + Σ z s / π`` with ``body`` the table's own floor ``c`` by default, or the
    natural body spectrum (sr⁻¹) that replaced it (:mod:`.body`)."""
    wl = table.wavelengths
    s_hats = basis.spectral_hats(wl)
    phi = basis.lobe_factor(x, wl).astype(np.float32)                   # (90, 90, Λ)
    body = floor if body is None else np.asarray(body, np.float64)
    c_new = body * (s_hats @ body_tint) + (s_hats @ lambert) / np.pi     # (Λ,)
    values = table.values - floor.astype(np.float32)
    values *= phi[:, :, None, :]
    values += c_new.astype(np.float32)
    if added is not None:
        values += basis.lobe_factor(added, wl).astype(np.float32)[:, :, None, :]
    np.maximum(values, 0.0, out=values)
    return BRDFTable(values, wl, table.channels, dict(table.metadata))


def directional_albedo(table: BRDFTable, theta_i_deg=(0.0, 30.0, 60.0, 75.0), n: int = 48) -> np.ndarray:
    """Directional albedo ``∫ f cosθo dωo`` (len(θi), Λ) by midpoint quadrature in (cos θo, φo)."""
    mu = (np.arange(n) + 0.5) / n
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    mm, pp = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - mm ** 2)
    wo = np.stack([s * np.cos(pp), s * np.sin(pp), mm], -1).reshape(-1, 3)
    d_omega = (1.0 / n) * (2 * np.pi / (2 * n))
    out = []
    for t in np.radians(theta_i_deg):
        wi = np.broadcast_to([math.sin(t), 0.0, math.cos(t)], wo.shape)
        out.append((table.eval(wi, wo) * mm.reshape(-1, 1)).sum(axis=0) * d_omega)
    return np.array(out)


def _energy_warnings(network: BRDFTable, refined: BRDFTable) -> list[str]:
    """Warn where the refined table reflects more energy than it receives and the network did not."""
    a_ref = directional_albedo(refined).max()
    a_net = directional_albedo(network).max()
    if a_ref > 1.0 + 1e-3 and a_net <= 1.0 + 1e-3:
        return [f"the refined material reflects up to {a_ref:.2f}× the light it receives (not energy "
                f"conserving): the photo is brighter than this lighting allows, its power too low for "
                f"this material (raise it, or the map's exposure; a light estimated or found in a chrome "
                f"ball had its power fitted, so the material's brightness is uncertain by that factor)"]
    return []
