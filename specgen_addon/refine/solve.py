"""Regularised, non-negative least squares for the correction coefficients (numpy only).

Minimises ``‖A θ − b‖² + Σ_k ρ_k (θ_k − θ0_k)² + ‖S θ‖²`` subject to ``θ ≥ 0``: the data term, a
pull towards the network's prediction ``θ0`` (so what the photo does not see stays with the prior)
and a smoothness term ``S`` between neighbouring knots. The problem is small (a few hundred
unknowns), so it is solved on its normal equations by an active-set method.
"""

from __future__ import annotations

import numpy as np

from ..errors import SpecGenError


def difference_operator(shape: tuple[int, ...], axis: int) -> np.ndarray:
    """First differences along ``axis`` of a C-ordered coefficient grid: (rows, prod(shape))."""
    n = int(np.prod(shape))
    idx = np.arange(n).reshape(shape)
    lo = np.take(idx, np.arange(shape[axis] - 1), axis=axis).ravel()
    hi = np.take(idx, np.arange(1, shape[axis]), axis=axis).ravel()
    d = np.zeros((lo.size, n))
    d[np.arange(lo.size), lo] = -1.0
    d[np.arange(lo.size), hi] = 1.0
    return d


def nonneg_ridge(gram: np.ndarray, rhs: np.ndarray, max_iter: int = 200) -> np.ndarray:
    """``argmin ½θᵀGθ − rᵀθ`` s.t. ``θ ≥ 0`` for symmetric positive-definite ``G``.

    Block-pivoting active set (Portugal, Júdice & Vicente 1994): coordinates that come out negative
    are bound at zero, a bound coordinate whose gradient points inside is released, until the KKT
    conditions hold. Converges in a few steps here, where the prior keeps most coordinates interior.
    """
    gram = np.asarray(gram, dtype=np.float64)
    rhs = np.asarray(rhs, dtype=np.float64)
    n = rhs.size
    if gram.shape != (n, n):
        raise SpecGenError("internal: Gram matrix and right-hand side disagree")
    free = np.ones(n, dtype=bool)
    theta = np.zeros(n)
    for _ in range(max_iter):
        sol = np.zeros(n)
        if np.any(free):
            sol[free] = np.linalg.solve(gram[np.ix_(free, free)], rhs[free])
        if np.all(sol[free] >= 0):
            theta = sol
            grad = gram @ theta - rhs                     # KKT: grad ≥ 0 on the bound set
            bound = ~free
            if not np.any(bound) or np.all(grad[bound] >= -1e-10 * (1 + np.abs(rhs[bound]))):
                return theta
            k = np.flatnonzero(bound)[np.argmin(grad[bound])]
            free[k] = True
            continue
        # bind every coordinate that went negative (block pivoting) and solve again
        free &= ~(sol < 0)
    return np.clip(theta, 0.0, None)
