"""Rusinkiewicz half/difference coordinates (Rusinkiewicz 1998), vectorised.

All directions are unit vectors in the local shading frame, normal ``n = (0, 0, 1)``, with shape
``(..., 3)``. Angles are in radians. ``h = normalize(wi + wo)``; ``theta_h`` is the polar angle of
``h``; the difference vector ``d`` is ``wi`` expressed in the frame where ``h`` is the pole
(rotate by ``-phi_h`` about ``n``, then by ``-theta_h`` about the binormal); ``theta_d``/``phi_d``
are its polar and azimuth angles. Swapping ``wi`` and ``wo`` maps ``phi_d`` to ``phi_d ± π``, so
for isotropic, reciprocal BRDFs ``phi_d`` folds into ``[0, π)`` (:func:`fold_phi_d`).
"""

from __future__ import annotations

import numpy as np

ArrayLike = np.ndarray


def _rotate_z(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


def _rotate_y(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def half_diff_from_io(wi: ArrayLike, wo: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Map directions ``(wi, wo)`` to ``(theta_h, theta_d, phi_d)`` in radians.

    ``phi_d`` is returned in ``(-π, π]`` (unfolded). Callers that index isotropic tables fold it
    with :func:`fold_phi_d`. The result is symmetric under ``wi <-> wo`` after folding.
    """
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    h = wi + wo
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    # wi = -wo (h undefined) never occurs for directions above the surface; guard anyway.
    h = np.where(norm > 1e-12, h / np.maximum(norm, 1e-12), np.array([0.0, 0.0, 1.0]))
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    d = _rotate_y(_rotate_z(wi, -phi_h), -theta_h)
    theta_d = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    phi_d = np.arctan2(d[..., 1], d[..., 0])
    return theta_h, theta_d, phi_d


def io_from_half_diff(theta_h: ArrayLike, theta_d: ArrayLike, phi_d: ArrayLike,
                      phi_h: ArrayLike = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`half_diff_from_io`: angles in radians to unit ``(wi, wo)``.

    ``phi_h`` is the azimuth of the half vector (irrelevant for isotropic BRDFs, default 0).
    """
    theta_h, theta_d, phi_d, phi_h = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, theta_d, phi_d, phi_h)))
    st_d = np.sin(theta_d)
    d = np.stack([st_d * np.cos(phi_d), st_d * np.sin(phi_d), np.cos(theta_d)], axis=-1)
    st_h = np.sin(theta_h)
    h = np.stack([st_h * np.cos(phi_h), st_h * np.sin(phi_h), np.cos(theta_h)], axis=-1)
    wi = _rotate_z(_rotate_y(d, theta_h), phi_h)
    # wo is the mirror of wi about h: wo = 2 (wi·h) h - wi.
    wo = 2.0 * np.sum(wi * h, axis=-1, keepdims=True) * h - wi
    return wi, wo


def fold_phi_d(phi_d: ArrayLike) -> np.ndarray:
    """Fold ``phi_d`` into ``[0, π)`` using reciprocity/isotropy (``phi_d ~ phi_d + π``)."""
    return np.mod(np.asarray(phi_d, dtype=np.float64), np.pi)
