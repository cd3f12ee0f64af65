"""Held-out pixels: does a looser fit predict the photo it was not fitted to?

A fit's own self-reproduction always rises as its regularisation is loosened, whether it fits the
material or the photo's noise (a real photo's, or the operator's sampling error, which is
independent per pixel: :mod:`specgen_addon.render.sampling`). Cross-validation tells the two apart:
the sphere's observed pixels are split into a checkerboard of square blocks, each half is fitted
alone, and the fit is scored on the other half. Noise fitted on one half does not predict the
other; the material does. Blocks rather than single pixels, because the photo's blur and its
resampling correlate neighbouring pixels' noise.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Side of the checkerboard's blocks (pixels of the photo's sphere crop): wider than the photo's
#: blur (σ ≤ 1.4 px, :data:`.blur.BLUR_CANDIDATES_PX`), so the two halves share little noise.
HOLDOUT_BLOCK_PX = 8

Solver = Callable[[np.ndarray, np.ndarray], np.ndarray]


def block_folds(shape: tuple[int, int], pixel_ids: np.ndarray, block_px: int = HOLDOUT_BLOCK_PX) -> np.ndarray:
    """Fold (0 or 1) of each observed pixel (flat indices ``pixel_ids`` of an image of ``shape``):
    the colour of its ``block_px``-square on a checkerboard."""
    if block_px < 1:
        raise ValueError(f"block_px must be ≥ 1, got {block_px}")
    y, x = np.divmod(np.asarray(pixel_ids, dtype=np.int64), int(shape[1]))
    return ((y // block_px + x // block_px) % 2).astype(np.int8)


def holdout_error(design: np.ndarray, photo: np.ndarray, folds: np.ndarray, solve: Solver) -> float:
    """Mean squared error (photo units) of each fold's pixels predicted by a fit to the other fold.

    ``design`` (P, 3, K) and ``photo`` (P, 3) are the fit's rows; ``solve(design, photo)`` returns
    the coefficients (K,) for a subset of them. ``inf`` when a fold is empty (nothing to hold out)."""
    return holdout_errors(design, photo, folds, [solve])[0]


def holdout_errors(design: np.ndarray, photo: np.ndarray, folds: np.ndarray, solvers: list[Solver]) -> list[float]:
    """:func:`holdout_error` of each of ``solvers``, the folds cut once: every solver is given the
    same fold arrays, so solvers that share work on a fold (its normal equations) can reuse it."""
    first = folds == 0
    if not np.any(first) or np.all(first):
        return [float("inf")] * len(solvers)
    # each fold's rows are cut once (the design is large): one fold's held rows are the other's fitted ones
    rows = [(design[first], photo[first]), (design[~first], photo[~first])]
    totals, count = [0.0] * len(solvers), 0
    for k in (0, 1):
        (held_design, held_photo), (fit_design, fit_photo) = rows[k], rows[1 - k]
        for i, solve in enumerate(solvers):
            theta = solve(fit_design, fit_photo)
            totals[i] += float(np.sum((held_design @ theta - held_photo) ** 2))
        count += held_photo.size
    return [t / count for t in totals]
