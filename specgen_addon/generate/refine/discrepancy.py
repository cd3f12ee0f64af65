"""How closely the photo can be fitted: the renderer's own sampling error, and the discrepancy principle.

The refinement's operator estimates each pixel with a fixed set of environment samples (56
directions per pixel for the input lighting). A real photo shares none of them, so even the true
material, rendered by the operator, misses the photo by the operator's sampling error. Fitting the
photo more closely than that fits the error: the correction bends the lobe until the operator's
noise matches the photo's, and the material gets worse (a shiny metal lost 11 dB of truth on such a
photo while its self-reproduction rose by 4 dB; docs/refinement.md).

The sampling error is measured, not assumed: the network's table is rendered twice under the
input's lighting, with the operator's samples and with an independent set (another seed), and
``n² = mean((R₀ − R₁)²) / 2`` is the per-render error variance (each of the two has it; their
difference has twice it). Morozov's discrepancy principle then sets the pull towards the network:
the correction may bring the residual down to ``τ n²`` and no further (``τ`` is
:attr:`~specgen_addon.generate.refine.RefineOptions.fit_floor`); where the network's own table is already
within it, the network is kept.
"""

from __future__ import annotations

import weakref
from dataclasses import replace

import numpy as np

_TWINS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def twin_scene(scene):
    """The same scene (geometry, lights, environment, camera) with independent environment
    samples (the sampling seed + 1), prepared once per scene."""
    twin = _TWINS.get(scene)
    if twin is None:
        twin = scene.with_sampling(replace(scene.sampling, seed=scene.sampling.seed + 1))
        _TWINS[scene] = twin
    return twin


def sampling_variance(rows_a: np.ndarray, rows_b: np.ndarray) -> float:
    """Per-render sampling-error variance ``mean((a − b)²) / 2`` of two renders of one table with
    independent samples (observed-pixel rows, photo units)."""
    return difference_variance(np.asarray(rows_a, np.float64) - np.asarray(rows_b, np.float64))


def difference_variance(difference: np.ndarray) -> float:
    """:func:`sampling_variance` from the difference ``a − b`` of the two renders (rows or an image,
    e.g. after both were blurred alike): ``mean(d²) / 2``, 0 for no pixels."""
    d = np.asarray(difference, np.float64)
    return float(np.mean(d * d) / 2.0) if d.size else 0.0


def discrepancy_scale(residual_at, target: float, lo: float = 1e-2, hi: float = 1e14) -> float:
    """The smallest factor ``s`` on the discrepancy pull whose fit leaves a mean squared residual of
    at least ``target``: 0 where the plain fit already does, ``inf`` (keep the prior's own
    coefficients) where even ``hi`` fits more closely. ``residual_at(s)`` must grow with ``s``
    (a ridge pull's does); bisection in log ``s`` to 5 % in the pull's strength."""
    if residual_at(0.0) >= target:
        return 0.0
    if residual_at(hi) < target:
        return float("inf")
    a, b = np.log(lo), np.log(hi)
    if residual_at(lo) >= target:
        return lo
    while b - a > 0.05:
        m = 0.5 * (a + b)
        if residual_at(float(np.exp(m))) >= target:
            b = m
        else:
            a = m
    return float(np.exp(b))
