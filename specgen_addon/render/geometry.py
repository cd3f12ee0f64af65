"""Geometry for the reference renderer: a normal map plus mask seen by an orthographic camera.

World frame (used by the whole renderer): +x right, +y up, +z towards the camera. The default
camera looks down −z, so the outgoing direction is ``wo = +z`` for every pixel. Image row 0 is the
top of the picture (+y), column 0 the left (−x).

Any surface whose per-pixel world normals are known (an analytic sphere here, a mesh's baked normal
map later) is a :class:`Geometry`. Shading happens in a per-pixel local frame whose +z is the normal
(:func:`shading_frame`, Duff et al. 2017, "Building an Orthonormal Basis, Revisited", JCGT 6(1)).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from specgen_addon.common.errors import SpecGenError


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise SpecGenError("direction vector has zero length")
    return v / n


@dataclass(frozen=True)
class OrthographicCamera:
    """An orthographic camera.

    ``direction`` is the unit vector from the scene *towards* the camera (the outgoing direction
    ``wo`` of every pixel); ``up`` is the image-up hint (made orthogonal to ``direction``).
    """

    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(right, up, back) unit vectors in world space; ``back`` = :attr:`direction`."""
        back = _unit(self.direction)
        up = np.asarray(self.up, dtype=np.float64)
        up = up - back * np.dot(up, back)
        if np.linalg.norm(up) < 1e-9:
            raise SpecGenError("camera up vector is parallel to the view direction")
        up = _unit(up)
        right = np.cross(up, back)
        return right, up, back


@dataclass
class Geometry:
    """Per-pixel world-space unit normals (H, W, 3) and a coverage mask (H, W) bool.

    ``view_dir`` is the world direction towards the camera (``wo`` for all pixels, orthographic).
    Pixels outside the mask, or facing away from the camera, are not shaded.
    """

    normals: np.ndarray
    mask: np.ndarray
    view_dir: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self) -> None:
        self.normals = np.asarray(self.normals, dtype=np.float64)
        self.mask = np.asarray(self.mask, dtype=bool)
        self.view_dir = _unit(self.view_dir)
        if self.normals.ndim != 3 or self.normals.shape[-1] != 3:
            raise SpecGenError(f"normal map must be H×W×3, got shape {self.normals.shape}")
        if self.mask.shape != self.normals.shape[:2]:
            raise SpecGenError(f"mask shape {self.mask.shape} does not match normal map "
                               f"{self.normals.shape[:2]}")
        valid = self.mask & np.all(np.isfinite(self.normals), axis=-1)
        lengths = np.linalg.norm(self.normals[valid], axis=-1)
        if np.any(np.abs(lengths - 1.0) > 1e-3):
            raise SpecGenError("normal map holds vectors that are not unit length inside the mask")
        self.mask = valid

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return self.normals.shape[0], self.normals.shape[1]

    @classmethod
    def from_normal_map(cls, normals: np.ndarray, mask: np.ndarray | None = None,
                        camera: OrthographicCamera = OrthographicCamera()) -> "Geometry":
        """Wrap a world-space normal map (e.g. baked from a mesh); ``mask`` defaults to non-zero normals."""
        normals = np.asarray(normals, dtype=np.float64)
        if mask is None:
            mask = np.linalg.norm(np.nan_to_num(normals), axis=-1) > 0.5
        n = np.where(np.asarray(mask)[..., None], normals, 0.0)
        lengths = np.linalg.norm(n, axis=-1, keepdims=True)
        n = np.divide(n, lengths, out=np.zeros_like(n), where=lengths > 0)
        return cls(n, mask, np.asarray(camera.direction, dtype=np.float64))


def pixel_grid(resolution: int | tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates (x, y) in [−1, 1] for an H×W image: x right, y up, row 0 on top."""
    h, w = (resolution, resolution) if isinstance(resolution, int) else resolution
    x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    y = 1.0 - (np.arange(h) + 0.5) / h * 2.0
    return np.meshgrid(x, y)


def sphere_geometry(resolution: int | tuple[int, int] = 128,
                    camera: OrthographicCamera = OrthographicCamera()) -> Geometry:
    """Analytic unit sphere filling the frame of an orthographic camera (radius = half the width).

    Pixel (x, y) in [−1, 1]² sees the sphere point ``x·right + y·up + sqrt(1 − x² − y²)·back`` whose
    normal is that same vector; the mask is ``x² + y² < 1`` at pixel centres.
    """
    x, y = pixel_grid(resolution)
    r2 = x * x + y * y
    mask = r2 < 1.0
    z = np.sqrt(np.clip(1.0 - r2, 0.0, None))
    right, up, back = camera.basis()
    n = x[..., None] * right + y[..., None] * up + z[..., None] * back
    n = np.where(mask[..., None], n, 0.0)
    return Geometry(n, mask, back)


def shading_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent and bitangent (…, 3) completing unit ``normals`` to a right-handed frame.

    Branchless construction of Duff et al. (2017); any tangent is valid for isotropic BRDFs.
    """
    n = np.asarray(normals, dtype=np.float64)
    nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(nz >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    t = np.stack([1.0 + sign * nx * nx * a, sign * b, -sign * nx], axis=-1)
    bt = np.stack([b, sign + ny * ny * a, -ny], axis=-1)
    return t, bt


def to_local(v: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """World vectors (…, 3) expressed in the frame (t, b, n), broadcasting over leading axes."""
    return np.stack([np.sum(v * t, -1), np.sum(v * b, -1), np.sum(v * n, -1)], axis=-1)


def smooth_normal(point: np.ndarray, corners: np.ndarray, corner_normals: np.ndarray) -> np.ndarray:
    """The unit normal at ``point`` inside a triangle of ``corners`` (3, 3), interpolated from its
    ``corner_normals`` (3, 3) with the point's barycentric coordinates: smooth shading, as a
    renderer interpolates a mesh's normals across a face."""
    a, b, c = np.asarray(corners, np.float64)
    v0, v1, v2 = b - a, c - a, np.asarray(point, np.float64) - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    wb = (d11 * d20 - d01 * d21) / den
    wc = (d00 * d21 - d01 * d20) / den
    n = np.array([1.0 - wb - wc, wb, wc]) @ np.asarray(corner_normals, np.float64)
    return n / np.linalg.norm(n)
