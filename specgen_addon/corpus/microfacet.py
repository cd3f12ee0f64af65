"""GGX microfacet specular lobe with Smith height-correlated masking-shadowing.

* Normal distribution (Walter et al. 2007, eq. 33), isotropic roughness ``α``:
  ``D(h) = α² / (π ((α² − 1) cos²θh + 1)²)``.
* Smith ``Λ(θ) = (−1 + sqrt(1 + α² tan²θ)) / 2`` and the height-correlated masking-shadowing
  ``G2 = 1 / (1 + Λ(θi) + Λ(θo))`` (Heitz 2014, eq. 99).
* Specular BRDF without Fresnel: ``D G2 / (4 cos θi cos θo)``; the caller multiplies by ``F``.

:func:`specular_albedo` gives the directional albedo ``E(μ)`` of the dielectric lobe (Fresnel
included) for the energy-conserving diffuse coupling of Kelemen & Szirmay-Kalos 2001, tabulated
once per process over ``(μ, α, η)`` by quadrature in the GGX-warped half-vector domain (exact for
near-mirror lobes, where a quadrature over outgoing directions would miss the peak).
"""

from __future__ import annotations

import functools

import numpy as np

from specgen_addon.corpus.fresnel import fresnel_dielectric


def ggx_d(cos_h: np.ndarray, alpha: float) -> np.ndarray:
    """GGX normal distribution ``D`` (sr⁻¹) at half-vector cosine ``cos_h``."""
    a2 = alpha * alpha
    c2 = np.asarray(cos_h, dtype=np.float64) ** 2
    t = (a2 - 1.0) * c2 + 1.0
    return np.where(c2 > 0.0, a2 / (np.pi * t * t), 0.0)


def smith_lambda(cos_theta: np.ndarray, alpha: float) -> np.ndarray:
    """Smith ``Λ`` for GGX; ``cos_theta`` ≤ 0 is treated as grazing (Λ large)."""
    c = np.maximum(np.asarray(cos_theta, dtype=np.float64), 1e-12)
    c2 = c * c
    tan2 = (1.0 - c2) / c2
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def smith_g2(cos_i: np.ndarray, cos_o: np.ndarray, alpha: float) -> np.ndarray:
    """Height-correlated masking-shadowing ``G2 = 1 / (1 + Λi + Λo)`` (symmetric in i, o)."""
    return 1.0 / (1.0 + smith_lambda(cos_i, alpha) + smith_lambda(cos_o, alpha))


def specular_geometry(cos_i: np.ndarray, cos_o: np.ndarray, cos_h: np.ndarray,
                      alpha: float) -> np.ndarray:
    """``D G2 / (4 cos θi cos θo)`` in sr⁻¹, zero when either direction is below the horizon."""
    cos_i = np.asarray(cos_i, dtype=np.float64)
    cos_o = np.asarray(cos_o, dtype=np.float64)
    valid = (cos_i > 0.0) & (cos_o > 0.0)
    denom = 4.0 * np.where(valid, cos_i * cos_o, 1.0)
    return np.where(valid, ggx_d(cos_h, alpha) * smith_g2(cos_i, cos_o, alpha) / denom, 0.0)


# --- Directional albedo table E(μ, α, η) of the dielectric GGX lobe --------------------------

#: Nodes of the albedo table: μ = cos θ uniform (linear interpolation, so the cosine-weighted
#: mean Ē is integrated exactly from the same interpolant), log α, η.
MU_NODES = np.linspace(0.0, 1.0, 65)
LOG_ALPHA_NODES = np.linspace(np.log(0.005), np.log(1.0), 33)
ETA_NODES = np.linspace(1.1, 2.3, 13)
_N_U, _N_PHI = 48, 32


@functools.lru_cache(maxsize=1)
def _albedo_table() -> np.ndarray:
    """``E[μ, log α, η]`` by Gauss–Legendre quadrature over the GGX-warped half vector.

    With ``tan²θh = α² u / (1 − u)``, ``D cos θh dω_h = du dφ / 2π``, and ``dω_o = 4 (wi·h) dω_h``,
    so ``E(wi) = ∫∫ F(wi·h) G2 (wi·h) / (μi cos θh) du dφ / 2π`` over ``wo`` above the horizon.
    """
    x, wx = np.polynomial.legendre.leggauss(_N_U)
    u = 0.5 * (x + 1.0)
    wu = 0.5 * wx
    phi = (np.arange(_N_PHI) + 0.5) * np.pi / _N_PHI  # symmetric about φ = 0: integrate [0, π]
    wphi = np.full(_N_PHI, 2.0 * np.pi / _N_PHI)
    mu = np.maximum(MU_NODES, 1e-3)[:, None, None, None]
    alpha = np.exp(LOG_ALPHA_NODES)[None, :, None, None]
    uu = u[None, None, :, None]
    tan2 = alpha ** 2 * uu / (1.0 - uu)
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(tan2) * cos_h
    pp = phi[None, None, None, :]
    sin_i = np.sqrt(1.0 - mu * mu)
    i_dot_h = sin_i * sin_h * np.cos(pp) + mu * cos_h
    cos_o = 2.0 * i_dot_h * cos_h - mu
    valid = (i_dot_h > 0.0) & (cos_o > 0.0)
    g2 = 1.0 / (1.0 + smith_lambda(mu, alpha) + smith_lambda(cos_o, alpha))
    weight = g2 * i_dot_h / (mu * cos_h) * (wu[:, None] * wphi[None, :]) / (2 * np.pi)
    shape = (MU_NODES.size, LOG_ALPHA_NODES.size)
    full = shape + (_N_U, _N_PHI)
    flat = (shape[0] * shape[1], _N_U * _N_PHI)
    valid = np.broadcast_to(valid, full).reshape(flat)
    weight = np.broadcast_to(weight, full).reshape(flat)
    c = np.broadcast_to(i_dot_h, full).reshape(flat)
    rows = np.broadcast_to(np.arange(flat[0])[:, None], flat)[valid]
    w, c = weight[valid], np.clip(c[valid], 0.0, 1.0)
    table = np.empty(shape + (ETA_NODES.size,))
    for j, eta in enumerate(ETA_NODES):
        table[:, :, j] = np.bincount(rows, w * fresnel_dielectric(c, eta),
                                     minlength=flat[0]).reshape(shape)
    table.setflags(write=False)
    return table


def _interp_weights(x: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the left node and the fractional position, for uniform ``nodes`` (clamped)."""
    t = (np.clip(x, nodes[0], nodes[-1]) - nodes[0]) / (nodes[1] - nodes[0])
    i = np.minimum(np.floor(t).astype(np.int64), nodes.size - 2)
    return i, t - i


def specular_albedo_curves(alpha: float, eta: np.ndarray) -> np.ndarray:
    """``E(μ)`` at :data:`MU_NODES` for roughness ``alpha`` and each ``eta``: shape (len(eta), 65).

    Bilinear in ``(log α, η)`` on the precomputed table; callers interpolate linearly in ``μ``.
    """
    table = _albedo_table()
    ia, fa = _interp_weights(np.array(np.log(alpha)), LOG_ALPHA_NODES)
    ie, fe = _interp_weights(np.asarray(eta, dtype=np.float64), ETA_NODES)
    ta = (1.0 - fa) * table[:, ia, :] + fa * table[:, ia + 1, :]  # (μ, η nodes)
    curves = (1.0 - fe) * ta[:, ie] + fe * ta[:, ie + 1]  # (μ, len(eta))
    return np.ascontiguousarray(curves.T)


def cosine_weighted_mean(curves: np.ndarray) -> np.ndarray:
    """``Ē = 2 ∫₀¹ E(μ) μ dμ`` of piecewise-linear curves on :data:`MU_NODES` (exact)."""
    a, b = MU_NODES[:-1], MU_NODES[1:]
    h = b - a
    ea, eb = curves[..., :-1], curves[..., 1:]
    return 2.0 * np.sum(h * (ea * (2 * a + b) + eb * (a + 2 * b)) / 6.0, axis=-1)


def lookup_mu(curves: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Evaluate curves (Λ, 65) at cosines ``mu`` (N,): returns (N, Λ), linear in ``μ``."""
    i, f = _interp_weights(np.asarray(mu, dtype=np.float64), MU_NODES)
    rows = np.ascontiguousarray(np.asarray(curves).T)  # (65, Λ): gather rows, not columns
    return rows[i] * (1.0 - f)[:, None] + rows[i + 1] * f[:, None]
