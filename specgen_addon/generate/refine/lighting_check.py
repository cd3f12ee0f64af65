"""Does the input lighting explain the photo? Two lighting-free figures beside the self-reproduction.

A refined table can reproduce its photo poorly for two reasons: the lighting it was given is
wrong, or the photo holds what no fit reproduces (interreflections, a stand, a lamp near the
ball, noise). On real photos the two overlap in decibels, so a threshold on the self-reproduction
alone warns about correct lights (on the shared grey-ball photos it did on 9 of 12). Two figures
tell them apart (lab/notebook/real-photos-network.md):

* a Lambertian ball under the best distant lighting of any kind. Its irradiance is, to within a
  few percent, a second-order spherical-harmonic function of the normal (Ramamoorthi & Hanrahan
  2001, "An Efficient Representation for Irradiance Environment Maps"), so it is a linear
  least-squares fit of 9 coefficients per channel to the same pixels. A refined table under the
  given lighting that reproduces the photo far worse than that matte ball under a light of its
  own choosing (by more than :data:`LIGHTING_MARGIN_DB`) names the lighting;
* where the residual lies: a wrong light on a glossy ball leaves it at the highlight, which no
  smooth table can put where the wrong light's θh is large, while a real photo's imperfections
  spread it over the ball. More than :data:`BRIGHT_SHARE` of the squared residual on the photo's
  brightest :data:`BRIGHT_PERCENT` % of pixels names the lighting too.

Both apply only under :data:`~specgen_addon.generate.refine.refinement.WARN_PSNR_DB`: a table that
reproduces its photo well is not questioned; one :data:`FAR_BELOW_DB` under it always is.
"""

from __future__ import annotations

import numpy as np

from specgen_addon.render.photo_reproduction import rgb_psnr

#: How much worse (dB) than the any-light Lambertian the refined self-reproduction may be before
#: the lighting is named (on the shared grey-ball photos the right light came within 7.0 dB).
LIGHTING_MARGIN_DB = 8.0
#: A self-reproduction this far (dB) under the warning's threshold is warned about whatever the
#: figures: nothing reproduces the photo (noise, not a ball), or nothing in it matches the lighting.
FAR_BELOW_DB = 10.0
#: The photo's brightest pixels (percent of the observed ones) where a highlight's residual lies.
BRIGHT_PERCENT = 5.0
#: Share of the squared residual on those pixels above which the lighting is named (on the shared
#: grey-ball photos the right light left at most 0.042 there).
BRIGHT_SHARE = 0.1


def sh9_basis(normals: np.ndarray) -> np.ndarray:
    """(N, 9) real spherical harmonics up to order 2 of unit ``normals`` (N, 3), unnormalised
    (only their span matters here)."""
    x, y, z = np.asarray(normals, np.float64).T
    return np.stack([np.ones_like(x), x, y, z, x * y, y * z, x * z, x * x - y * y, 3 * z * z - 1], 1)


def any_light_lambertian_db(rows: np.ndarray, normals: np.ndarray, fitted: np.ndarray | None = None,
                            full_scale: float | np.ndarray | None = None, scale: float | None = None) -> float | None:
    """RGB PSNR (dB, :func:`~specgen_addon.render.photo_reproduction.rgb_psnr`) of the best
    Lambertian ball under any distant lighting against the photo's rows (P, 3), pixel normals
    (P, 3) in any fixed frame; fitted to the rows where ``fitted`` (P,) is True (default: all),
    scored on all, clipped at ``full_scale`` (per channel) as the camera clips (None: not clipped).
    None with fewer than 9 rows."""
    rows = np.asarray(rows, np.float64)
    keep = np.ones(rows.shape[0], bool) if fitted is None else np.asarray(fitted, bool)
    if keep.sum() < 9:
        return None
    basis = sh9_basis(normals)
    coef, *_ = np.linalg.lstsq(basis[keep], rows[keep], rcond=None)
    pred = basis @ coef
    if full_scale is not None:
        pred = np.minimum(pred, full_scale)
    return rgb_psnr(rows, pred, scale)


def bright_residual_share(rows: np.ndarray, rendered_rows: np.ndarray) -> float | None:
    """Share of the squared residual (``rendered_rows`` − ``rows``, both (P, 3)) that lies on the
    photo's brightest :data:`BRIGHT_PERCENT` % of pixels (by mean of R, G, B); None for a perfect
    fit or no pixels."""
    rows = np.asarray(rows, np.float64)
    if rows.shape[0] == 0:
        return None
    lum = rows.mean(1)
    top = lum >= np.percentile(lum, 100.0 - BRIGHT_PERCENT)
    err = ((np.asarray(rendered_rows, np.float64) - rows) ** 2).sum(1)
    total = float(err.sum())
    return float(err[top].sum()) / total if total > 0 else None


def lighting_suspect(refined_db: float, reference_db: float | None, bright_share: float | None,
                     below_db: float) -> bool:
    """Whether a refined self-reproduction ``refined_db`` names the lighting as the suspect: under
    ``below_db``, and either more than :data:`LIGHTING_MARGIN_DB` under the any-light
    Lambertian's ``reference_db`` or with more than :data:`BRIGHT_SHARE` of its residual on the
    brightest pixels (``bright_share``), or :data:`FAR_BELOW_DB` under ``below_db``. Without
    either figure, under ``below_db`` alone."""
    return _suspect_because(refined_db, reference_db, bright_share, below_db) is not None


def _suspect_because(refined_db: float, reference_db: float | None, bright_share: float | None,
                     below_db: float) -> str | None:
    """:func:`lighting_suspect` as the clause the warning quotes ("" when no figure names the
    lighting but the self-reproduction is too low anyway), or None when it is not suspect."""
    if refined_db >= below_db:
        return None
    if reference_db is not None and refined_db < reference_db - LIGHTING_MARGIN_DB:
        return f", where a matte ball under a light of its own choosing reaches {reference_db:.1f} dB"
    if bright_share is not None and bright_share > BRIGHT_SHARE:
        return (f", with {100 * bright_share:.0f}% of its error on the photo's brightest pixels "
                f"(a highlight this lighting does not put there)")
    if (reference_db is None and bright_share is None) or refined_db < below_db - FAR_BELOW_DB:
        return ""
    return None


def lighting_warning(refined_db: float, reference_db: float | None, bright_share: float | None,
                     below_db: float, studio: bool = False) -> str | None:
    """The run's warning when :func:`lighting_suspect` names the lighting (one sentence), else None.

    Under the canonical studio (``studio``: what a run assumes when no light is given) any figure
    under ``below_db`` is warned about: the studio is an assumption, not what the user said of the
    room, and a real photo is rarely lit like it (on the shared grey-ball photos the refined table
    then predicts the other photos at 15.3 dB)."""
    if studio and refined_db < below_db:
        return (f"the canonical studio (assumed when no light is given) does not explain this photo: "
                f"self-reproduction reaches only {refined_db:.1f} dB (give the room's light: a light's "
                f"direction, a chrome ball, a panorama, or have it estimated)")
    why = _suspect_because(refined_db, reference_db, bright_share, below_db)
    if why is None:
        return None
    return (f"the chosen lighting does not explain this photo: self-reproduction reaches only "
            f"{refined_db:.1f} dB{why} (check the input lighting, exposure and image)")
