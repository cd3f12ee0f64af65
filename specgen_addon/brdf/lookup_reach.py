"""The MERL grid nodes that a lookup at an above-horizon direction pair can touch.

A tabulated BRDF is read only by :meth:`specgen_addon.brdf.table.BRDFTable.eval_hd` (trilinear in
√θh, θd and φd) at direction pairs with both ωi and ωo above the horizon; everything else is zero
(:meth:`~specgen_addon.brdf.table.BRDFTable.eval`). In the half/difference frame (Rusinkiewicz 1998; h
tilted by θh in the xz-plane, d at (θd, φd) about h)::

    cos θi = cos θh cos θd − sin θh sin θd cos φd,   cos θo = cos θh cos θd + sin θh sin θd cos φd,

so a pair lies above the horizon exactly where ``|cos φd| < cot θh · cot θd``. About a fifth of the
grid's nodes lie so far below it that no lookup reaches them, and a generated table need not
compute them (:func:`specgen_addon.model.runtime.inference.evaluate_grid`).

A node is *reached* when it is a corner of a lookup cell (``[a, a+1] × [b, b+1] × [k, k+1]`` in
index space, θh and θd clamped to the last cell as ``eval_hd`` clamps them, φd periodic) whose
closure holds an above-horizon pair. ``cot θh cot θd`` falls with both angles, so a cell holds one
iff ``cot θh(a) cot θd(b) > min |cos φd|`` over its φd span: exact, no sampling. At each (θh, θd)
node the reached φd nodes are one run about φd = 90° (:func:`phi_d_reach`).
"""

from __future__ import annotations

import functools

import numpy as np

from specgen_addon.brdf.table import N_PHI_D, N_THETA_D, N_THETA_H, grid_angles

#: Slack on ``|cos φd| < cot θh cot θd``: a pair that float rounding puts on the horizon still counts.
HORIZON_SLACK = 1e-6


@functools.lru_cache(maxsize=1)
def phi_d_reach() -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)``, each (90, 90) int: at θh node i and θd node j the φd nodes ``lo[i, j] …
    hi[i, j]`` (inclusive) are the ones an above-horizon lookup can touch; every other φd node of
    that row is never read. Computed once, returned read-only."""
    th, td, _ = grid_angles()
    # the most favourable cell with node (i, j) as a corner starts at node max(i − 1, 0)
    cot_h = _cot(th[np.maximum(np.arange(N_THETA_H) - 1, 0)])
    cot_d = _cot(td[np.maximum(np.arange(N_THETA_D) - 1, 0)])
    reach = cot_h[:, None] * cot_d[None, :]                  # (90, 90); ∞ at θ = 0, never 0 · ∞
    # node p is a corner of the cells over [p − 1, p + 1] (periodic): min |cos φd| over that span
    p = np.arange(N_PHI_D, dtype=np.float64)
    nearest = np.clip(N_PHI_D / 2, p - 1.0, p + 1.0)        # the span's point closest to φd = 90°
    min_cos = np.abs(np.cos(nearest / N_PHI_D * np.pi))
    reached = min_cos[None, None, :] < reach[:, :, None] + HORIZON_SLACK       # (90, 90, 180)
    lo = np.argmax(reached, axis=2)
    hi = N_PHI_D - 1 - np.argmax(reached[:, :, ::-1], axis=2)
    for a in (lo, hi):
        a.flags.writeable = False
    return lo, hi


def _cot(theta: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.cos(theta) / np.sin(theta)               # +∞ at θ = 0


def reached_fraction() -> float:
    """Share of the grid's (θh, θd, φd) nodes that a lookup can touch."""
    lo, hi = phi_d_reach()
    return float((hi - lo + 1).sum() / (N_THETA_H * N_THETA_D * N_PHI_D))


def extend_beyond_reach(rows: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Give the unreached φd nodes of ``rows`` (…, 180, C) the value of the nearest reached one,
    in place (``lo``, ``hi``: the rows' reach, shape …): a table is then defined everywhere, with
    no value a lookup could ever see changed."""
    for index in np.ndindex(*lo.shape):
        a, b = int(lo[index]), int(hi[index])
        row = rows[index]
        if a > 0:
            row[:a] = row[a]
        if b < N_PHI_D - 1:
            row[b + 1:] = row[b]
