"""numpy twins of the few scipy.ndimage / scikit-image calls that find the sphere in a photo.

A stock Blender has numpy but neither scipy nor scikit-image; :mod:`specgen_addon.photo.sphere_image`
falls back to these where those packages are missing. Same names, arguments and defaults as
scipy's (cross-shaped 4-connectivity, ``border_value=0``, ``mode="nearest"``,
``truncate=4.0``); the tests check them against scipy and scikit-image.
"""

from __future__ import annotations

import numpy as np


def _shift(a: np.ndarray, dy: int, dx: int, fill) -> np.ndarray:
    """``out[y, x] = a[y - dy, x - dx]``, ``fill`` where that falls outside."""
    out = np.full_like(a, fill)
    h, w = a.shape
    out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = \
        a[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
    return out


_CROSS = ((0, 1), (0, -1), (1, 0), (-1, 0))


def binary_erosion(mask: np.ndarray, iterations: int = 1) -> np.ndarray:
    """Erosion by the 3×3 cross; outside the image counts as background."""
    m = np.asarray(mask, bool)
    for _ in range(iterations):
        out = m.copy()
        for dy, dx in _CROSS:
            out &= _shift(m, dy, dx, False)
        m = out
    return m


def binary_dilation(mask: np.ndarray, iterations: int = 1) -> np.ndarray:
    """Dilation by the 3×3 cross."""
    m = np.asarray(mask, bool)
    for _ in range(iterations):
        out = m.copy()
        for dy, dx in _CROSS:
            out |= _shift(m, dy, dx, False)
        m = out
    return m


def binary_opening(mask: np.ndarray, iterations: int = 1) -> np.ndarray:
    """Erosion then dilation (removes specks thinner than the cross)."""
    return binary_dilation(binary_erosion(mask, iterations), iterations)


def label(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """4-connected components: (labels 1…n in raster order of first pixel, 0 = background, n).

    Run-based: each row's runs of foreground are the nodes, runs of neighbouring rows that
    overlap are joined (min-label propagation with pointer jumping over the runs), and the runs
    are painted back. A photo has far fewer runs than pixels, so this costs a few array passes
    instead of one per pixel a label must travel."""
    m = np.asarray(mask, bool)
    h, w = m.shape
    edges = np.diff(np.pad(m, ((0, 0), (1, 1))).astype(np.int8), axis=1)
    row, start = np.nonzero(edges == 1)          # raster order: by row, then by column
    end = np.nonzero(edges == -1)[1]             # one past each run's last pixel
    n = row.size
    if n == 0:
        return np.zeros((h, w), np.int32), 0
    # the runs of row r - 1 touching run b of row r: an index range of the raster-ordered runs
    stride = w + 2
    lo = np.searchsorted(row * stride + end, (row - 1) * stride + start, side="right")
    hi = np.searchsorted(row * stride + start, (row - 1) * stride + end, side="left")
    count = np.maximum(hi - lo, 0)
    b = np.repeat(np.arange(n), count)
    a = np.repeat(lo, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    root = np.arange(n)
    while True:  # every run takes the smallest run index of its component
        prev = root
        low = np.minimum(root[a], root[b])
        root = root.copy()
        np.minimum.at(root, a, low)
        np.minimum.at(root, b, low)
        for _ in range(4):
            root = root[root]
        if np.array_equal(root, prev):
            break
    first, run_label = np.unique(root, return_inverse=True)   # the smallest index: first in raster order
    out = np.zeros(h * w, np.int32)
    length = end - start
    pixel = np.repeat(row * w + start - (np.cumsum(length) - length), length) + np.arange(length.sum())
    out[pixel] = np.repeat(run_label.reshape(-1) + 1, length)
    return out.reshape(h, w), int(first.size)


def sum(values: np.ndarray, labels: np.ndarray, index) -> np.ndarray:  # noqa: A001 (scipy's name)
    """Sum of ``values`` over each label in ``index``."""
    totals = np.bincount(np.ravel(labels), weights=np.ravel(values).astype(np.float64))
    index = np.asarray(index)
    return np.where(index < totals.size, totals[np.minimum(index, totals.size - 1)], 0.0)


def binary_fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` plus every background region not 4-connected to the image border."""
    m = np.asarray(mask, bool)
    lab, _ = label(~m)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    return m | ~np.isin(lab, border[border > 0]) & ~m


def _gaussian_kernel(sigma: float, truncate: float = 4.0) -> np.ndarray:
    radius = int(truncate * sigma + 0.5)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def gaussian_matrix(n: int, sigma: float, mode: str, truncate: float = 4.0) -> np.ndarray:
    """(n, n) matrix of the 1-D Gaussian correlation along an axis of length ``n``: taps that fall
    beyond the edge are dropped (``"constant"``) or land on the edge sample (``"nearest"``)."""
    k = _gaussian_kernel(sigma, truncate)
    r = k.size // 2
    rows = np.repeat(np.arange(n), k.size)
    cols = rows + np.tile(np.arange(-r, r + 1), n)
    weights = np.tile(k, n)
    if mode == "constant":
        inside = (cols >= 0) & (cols < n)
        rows, cols, weights = rows[inside], cols[inside], weights[inside]
    else:
        cols = np.clip(cols, 0, n - 1)
    m = np.zeros((n, n))
    np.add.at(m, (rows, cols), weights)
    return m


#: Axes up to this length are blurred as one matrix product (BLAS), longer ones tap by tap: the
#: product costs n multiply-adds per value against the taps' 2r + 1 passes over the array, and on
#: the refinement's 128 × 128 × 702 design stacks it is 3–7× faster than the taps and faster than
#: scipy (docs/refinement.md, "Speed and memory").
MATRIX_AXIS_MAX = 256


def gaussian_filter(a: np.ndarray, sigma, mode: str = "nearest", truncate: float = 4.0) -> np.ndarray:
    """Separable Gaussian blur with edge replication (``mode="nearest"``) or zeros beyond the edge
    (``mode="constant"``, cval 0); scipy's kernel (radius ``int(truncate·σ + 0.5)``)."""
    if mode not in ("nearest", "constant"):
        raise ValueError("only mode='nearest' and mode='constant' are implemented")
    out = np.asarray(a, dtype=np.float64)
    sigmas = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (out.ndim,))
    for axis, s in enumerate(sigmas):
        if s <= 0:
            continue
        n = out.shape[axis]
        if n <= MATRIX_AXIS_MAX:
            m = gaussian_matrix(n, float(s), mode, truncate)
            out = np.moveaxis(np.tensordot(m, out, axes=([1], [axis])), 0, axis)
            continue
        k = _gaussian_kernel(float(s), truncate)
        r = k.size // 2
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        padded = np.pad(out, pad, mode="edge" if mode == "nearest" else "constant")
        acc = np.zeros_like(out)
        for i, weight in enumerate(k):
            acc += weight * np.take(padded, np.arange(i, i + n), axis=axis)
        out = acc
    return np.ascontiguousarray(out)


def map_coordinates(a: np.ndarray, coords, order: int = 1, mode: str = "nearest") -> np.ndarray:
    """Bilinear sampling of a 2-D array at (row, column) coordinates, edges replicated."""
    if order != 1 or mode != "nearest":
        raise ValueError("only order=1, mode='nearest' is implemented")
    a = np.asarray(a, dtype=np.float64)
    h, w = a.shape
    y = np.clip(np.asarray(coords[0], np.float64), 0, h - 1)
    x = np.clip(np.asarray(coords[1], np.float64), 0, w - 1)
    y0 = np.minimum(np.floor(y).astype(int), max(h - 2, 0))
    x0 = np.minimum(np.floor(x).astype(int), max(w - 2, 0))
    ty, tx = y - y0, x - x0
    y1, x1 = np.minimum(y0 + 1, h - 1), np.minimum(x0 + 1, w - 1)
    return ((1 - ty) * ((1 - tx) * a[y0, x0] + tx * a[y0, x1]) +
            ty * ((1 - tx) * a[y1, x0] + tx * a[y1, x1]))


def fit_circle(pts: np.ndarray) -> np.ndarray:
    """Least-squares (algebraic, Kåsa) circle through points (N, 2): (cx, cy, r)."""
    x, y = pts[:, 0], pts[:, 1]
    a = np.stack([x, y, np.ones_like(x)], -1)
    b = x * x + y * y
    (c0, c1, c2), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = c0 / 2, c1 / 2
    return np.array([cx, cy, np.sqrt(max(c2 + cx * cx + cy * cy, 0.0))])


def ransac_circle(pts: np.ndarray, residual_threshold: float = 1.5, max_trials: int = 200,
                  seed: int = 0):
    """RANSAC circle fit as ``skimage.measure.ransac(pts, CircleModel, min_samples=3, ...)``:
    returns (model with ``.params = (cx, cy, r)``, inlier mask) or (None, None)."""
    pts = np.asarray(pts, dtype=np.float64)
    rng = np.random.default_rng(seed)
    best, best_count, best_err = None, 0, np.inf
    for _ in range(max_trials):
        sample = pts[rng.choice(len(pts), 3, replace=False)]
        (ax, ay), (bx, by), (cx, cy) = sample
        d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
        if abs(d) < 1e-12:
            continue
        ux = ((ax * ax + ay * ay) * (by - cy) + (bx * bx + by * by) * (cy - ay) + (cx * cx + cy * cy) * (ay - by)) / d
        uy = ((ax * ax + ay * ay) * (cx - bx) + (bx * bx + by * by) * (ax - cx) + (cx * cx + cy * cy) * (bx - ax)) / d
        r = np.hypot(ax - ux, ay - uy)
        resid = np.abs(np.hypot(pts[:, 0] - ux, pts[:, 1] - uy) - r)
        inliers = resid < residual_threshold
        count, err = int(inliers.sum()), float(np.sum(resid[inliers] ** 2))
        if count > best_count or (count == best_count and err < best_err):
            best, best_count, best_err = inliers, count, err
    if best is None or best_count < 3:
        return None, None

    class _Model:
        params = fit_circle(pts[best])

    return _Model(), best
