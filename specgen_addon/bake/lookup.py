"""Bake a spectral BRDF table and a scene's lighting into the textures the OSL shader reads.

No ``bpy`` here; the Blender side fills :class:`SceneLights` from the scene.

**Spectral basis.** Rendering is linear in the BRDF and in the light, so the spectral render need
not carry every wavelength through Cycles. The table's spectra are factored as
``f_r(θh, θd, φd, λ) ≈ Σ_k c_k(θh, θd, φd) B_k(λ)`` (principal components of the table entries'
spectral shapes, :func:`spectral_basis`), and lights and environment texels are RGB
uplifted linearly as ``E(λ) = Σ_c rgb_c U_c(λ)`` (Mallett & Yuksel 2019 basis × D65, the
reference renderer's convention). Then the spectral radiance is

    L(λ) = Σ_c Σ_k U_c(λ) B_k(λ) I_ck,   I_ck = Σ_lights c_k(ω_l) rgb_lc (n·ω_l)⁺ V + ∫ env …

and Cycles only renders the images ``I_ck``: four coefficient slots (one RGBA lookup group, two
bilinear taps for the trilinear interpolation) per Cycles render, RGB each, out through four colour
passes. Cycles drops or clamps negative closure weights (only Emission keeps them), so the signed
coefficients are stored shifted *in proportion to the first one*: ``B_0 ≥ 0`` (the Perron vector
of a non-negative Gram matrix), so ``c_0 ≥ 0``, and slot ``k`` holds ``c_k + o_k c_0 ≥ 0`` with
``o_k = max(−c_k / c_0)`` (``o_0 = 0``); the images then give ``I_ck = I'_ck − o_k I'_c0`` (exact,
linear). A shift proportional to each entry keeps float32 precision everywhere: a constant shift
``c_k + o_k`` must cover the brightest specular peak (``o_k`` reached 10⁴–10⁵ sr⁻¹ on generated
tables) and left the dim body colour below float32 resolution. ``K`` is the smallest of 4, 8,
12, … (filling whole renders) whose truncation error is below a tolerance, or Λ (exact), so 21
bands usually need one or two renders instead of Λ/3.

Files (float32 OpenEXR):

* **coefficient atlas** (:func:`bake_atlas`): one 90×90 tile per ``φd`` sample (x = √-warped
  ``θh`` index, y = ``θd`` index, MERL index maths), tiles row-major, one tiled RGBA file per group
  of four coefficients;
* **environment** (:func:`bake_environment`): the equirect radiance (RGB) with its sampling
  density in alpha, and a list of directions drawn from that density.

Wavelengths are nanometres, angles radians, directions Blender world vectors (z up).
"""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path, PureWindowsPath
from typing import Callable

import numpy as np

from specgen_addon.common.errors import Cancelled, OutputExistsError, SpecGenError
from specgen_addon.common.atomic_io import atomic_write, make_output_dir
from specgen_addon.common.limits import check_output_dir
from specgen_addon.brdf.table import N_PHI_D, N_THETA_D, N_THETA_H
from specgen_addon.bake.closure_fit import ClosureFit, fit_closures
from specgen_addon.bake.closure_fit.sheen import fit_sheen
from specgen_addon.bake.preview import write_preview
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import grid_angles, phi_d_index, theta_d_index, theta_h_index
from specgen_addon.common.image_io import read_exr, write_exr
from specgen_addon.common.limits import safe_name
from specgen_addon.render.environment import srgb_luminance_weights

COEFFS_PER_RENDER = 4   # coefficient slots per Cycles render: one RGBA lookup group, 4 passes
#: Atlas layout: 2 = slots c_k + o_k c_0 (1 had a constant slot 0 and absolute shifts).
ATLAS_VERSION = 2
DEFAULT_TOLERANCE = 1e-2  # relative RMS spectral error per entry, see spectral_basis
SHAPE_FLOOR = 1e-3       # entries below this fraction of the median count as that dark
MAX_LIGHTS = 4  # lights the shader takes as sockets (Light0… Light3)
ENV_LIST_WIDTH = 256


def _write_exr(path: Path, channels: dict[str, np.ndarray], overwrite: bool = True,
               attributes: dict[str, str] | None = None, tiled: bool = False) -> Path:
    # tiled: OIIO's texture cache reads tiles directly instead of re-tiling scanlines

    return write_exr(path, channels, overwrite=overwrite, attributes=attributes, tiled=tiled,
                     compression="none" if tiled else "zip")


def group_path(base: Path, group: int) -> Path:
    """File of coefficient group ``group`` of the atlas ``base`` (``a.exr`` -> ``a.g00.exr``)."""
    base = Path(base)
    return base.with_name(f"{base.stem}.g{group:02d}{base.suffix or '.exr'}")


def group_paths_of(base: Path, n_renders: int) -> list[Path]:
    """The ``n_renders`` group files of the atlas ``base`` (:func:`group_path`)."""
    return [group_path(base, g) for g in range(n_renders)]


def _fit_standins(table, wavelengths_nm: np.ndarray | None):
    """The native closure fit of ``table`` (its rendered error checked) with the Principled
    stand-in's sheen where the material needs one."""

    fit = fit_closures(table, wavelengths_nm, check=True)
    sheen = fit_sheen(lambda wi, wo: table.eval(wi, wo, fit.wavelengths_nm), fit)
    fit.sheen = None if sheen is None else sheen.to_dict()
    return fit


@dataclass
class AtlasInfo:
    """What :func:`bake_atlas` wrote.

    ``basis`` (K, Λ) holds the spectral basis ``B_k(λ)`` at ``wavelengths_nm`` (``B_0 ≥ 0``) and
    ``offsets`` (K,) the relative shifts ``o_k`` (``o_0 = 0``): slot ``k`` holds ``c_k + o_k c_0``; group file
    ``g`` holds slots ``4g … 4g+3`` in R, G, B, A. ``rel_error`` is the basis' relative RMS
    spectral error per table entry (:func:`spectral_basis`; 0 when exact). ``closures`` is the table's
    Lambert + GGX fit (:mod:`specgen_addon.bake.closure_fit.closures`) that the full-scene render uses.
    """

    path: Path
    wavelengths_nm: np.ndarray
    basis: np.ndarray
    offsets: np.ndarray
    n_phi_d: int
    tiles_x: int
    tiles_y: int
    rel_error: float = 0.0
    closures: ClosureFit | None = None  # native closure fit for the full-scene render
    refinement: object | None = None   # specgen_addon.generate.refine.RefineResult of a generated table
    film_fit: object | None = None     # specgen_addon.generate.thin_film.ThinFilmFit (model "thin-film")
    crop: object | None = None         # specgen_addon.photo.sphere_image.SphereCrop: the circle used

    @property
    def n_coeffs(self) -> int:
        return int(self.basis.shape[0])

    @property
    def n_slots(self) -> int:
        return self.n_coeffs

    @property
    def n_renders(self) -> int:
        """Cycles renders of a spectral stack: one per group of four slots."""
        return -(-self.n_slots // COEFFS_PER_RENDER)

    @property
    def group_paths(self) -> list[Path]:
        return group_paths_of(self.path, self.n_renders)


def atlas_layout(n_phi_d: int) -> tuple[int, int]:
    """(tiles_x, tiles_y) of an atlas with ``n_phi_d`` tiles: near-square, tiles_x divides n_phi_d."""
    best = (n_phi_d, 1)
    for tx in range(1, n_phi_d + 1):
        if n_phi_d % tx == 0:
            ty = n_phi_d // tx
            if abs(tx * N_THETA_H - ty * N_THETA_D) < abs(best[0] * N_THETA_H - best[1] * N_THETA_D):
                best = (tx, ty)
    return best


def resample_phi_d(values: np.ndarray, n_phi_d: int) -> np.ndarray:
    """Table values (90, 90, 180, C) resampled to ``n_phi_d`` φd samples at ``k·π/n_phi_d``.

    Linear interpolation with the table's own periodic φd weights, so ``n_phi_d = 180`` is the
    identity and the shader's interpolation on the coarse grid is the table's at its nodes.
    """
    if n_phi_d == N_PHI_D:
        return values
    if n_phi_d < 2 or n_phi_d > N_PHI_D:
        raise SpecGenError(f"lookup resolution must be 2–{N_PHI_D} φd samples, got {n_phi_d}")
    x = np.arange(n_phi_d) / n_phi_d * N_PHI_D
    k0 = np.floor(x).astype(int) % N_PHI_D
    k1 = (k0 + 1) % N_PHI_D
    t = (x - np.floor(x))[None, None, :, None]
    return (1 - t) * values[:, :, k0] + t * values[:, :, k1]


def spectral_basis(values: np.ndarray, tolerance: float = DEFAULT_TOLERANCE,
                   max_coeffs: int | None = None,
                   reachable: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Principal spectral basis of table entries ``values`` (…, Λ): ``(B (K, Λ), rel_error)``.

    The basis fits the *shape* of every entry's spectrum, not its energy: ``B``'s rows are the
    leading orthonormal eigenvectors of ``G = Σ_i w_i m_i m_iᵀ`` with ``w_i = r_i / (‖m_i‖² + ε²)``,
    ``ε = SHAPE_FLOOR · median_i ‖m_i‖`` (a PCA of the entries' spectra normalised to unit length;
    entries darker than the floor count as that dark) and ``r_i`` = 1 for entries a render can
    reach, 0 for the rest (``reachable``, same leading shape as ``values``: table entries whose
    directions lie below the horizon are never looked up, yet a generated table fills them, up to
    10⁵ sr⁻¹ at grazing angles, which a maximum-based floor or an energy weighting would chase). An energy-weighted PCA (``w_i = 1``) spends
    its few components on the bright specular peak and loses the body colour, which covers most
    pixels of a render: on the refined demo table its 3 components left a mean ΔE2000 of 2.8 in
    the reference render, against 0.4 for these (docs/blender.md).

    ``B_0`` is made non-negative (see :func:`bake_atlas`'s shifts). ``rel_error`` is the weighted relative RMS residual ``√(Σ w_i ‖m_i − m_i BᵀB‖² / Σ w_i ‖m_i‖²)``
    (the tail of ``G``'s eigenvalues): the typical relative spectral error of one entry. ``K`` is
    the smallest of 4, 8, 12, … (whole groups of four slots) whose error is
    ≤ ``tolerance``, capped at Λ where the basis is complete and exact; ``max_coeffs`` caps K.
    """
    lam = values.shape[-1]
    m = values.reshape(-1, lam)
    r = None if reachable is None else np.broadcast_to(reachable, values.shape[:-1]).reshape(-1)
    step = 1 << 18                     # entries per float64 chunk (bounded memory)

    def chunks():
        return ((s, m[s:s + step].astype(np.float64)) for s in range(0, m.shape[0], step))

    norms2 = np.concatenate([np.einsum("nl,nl->n", c, c) for _, c in chunks()])
    seen = norms2 > 0 if r is None else (norms2 > 0) & r
    eps2 = max(SHAPE_FLOOR ** 2 * float(np.median(norms2[seen])) if np.any(seen) else 0.0, 1e-300)
    w_all = 1.0 / (norms2 + eps2) if r is None else r / (norms2 + eps2)
    gram = np.zeros((lam, lam))
    for start, chunk in chunks():
        gram += (chunk * w_all[start:start + step, None]).T @ chunk
    eig, vec = np.linalg.eigh(gram)
    order = np.argsort(eig)[::-1]
    eig, vec = np.clip(eig[order], 0.0, None), vec[:, order]
    if vec[:, 0].sum() < 0:            # the Perron vector, made non-negative
        vec[:, 0] = -vec[:, 0]
    vec[:, 0] = np.clip(vec[:, 0], 0.0, None)
    total = max(float(eig.sum()), 1e-300)
    limit = lam if max_coeffs is None else max(1, min(lam, max_coeffs))
    k = COEFFS_PER_RENDER
    while True:
        k = min(k, limit)
        rel = float(np.sqrt(eig[k:].sum() / total)) if k < lam else 0.0
        if rel <= tolerance or k >= limit:
            return vec[:, :k].T.copy(), rel
        k += COEFFS_PER_RENDER


@functools.lru_cache(maxsize=4)
def reachable_entries(n_phi_d: int = N_PHI_D) -> np.ndarray:
    """(90, 90, n_phi_d) bool: grid entries whose (ωi, ωo) both lie above the horizon, allowing
    the one-cell reach of the trilinear lookup (a neighbour of a reachable node counts).

    A constant of the lookup resolution, so it is made once per resolution (0.4 s) and returned
    read-only."""
    th, td, _ = grid_angles()
    pd = np.arange(n_phi_d) / n_phi_d * np.pi
    wi, wo = io_from_half_diff(th[:, None, None], td[None, :, None], pd[None, None, :])
    above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    grown = above.copy()
    for axis in range(3):
        grown |= np.roll(above, 1, axis) | np.roll(above, -1, axis)
    grown.flags.writeable = False
    return grown


def shifted_coefficients(coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slots ``c_k + o_k c_0 ≥ 0`` of coefficients ``coeffs`` (…, K) and the shifts ``o`` (K,).

    Cycles keeps only non-negative closure weights. ``c_0`` (on the non-negative ``B_0``) is ≥ 0
    up to rounding; ``o_k = max(0, max(−c_k / c_0))`` over every entry with ``c_0 > 0`` (however
    dim: the body of a table whose peak is 10⁵ sr⁻¹ sits far below any fixed fraction of it),
    ``o_0 = 0``. Only entries with ``c_0 ≤ 0`` (zero spectra) are clipped.
    """
    coeffs = np.asarray(coeffs)
    k = coeffs.shape[-1]
    c0 = np.maximum(coeffs[..., 0].astype(np.float64), 0.0)   # one slot at a time, in float64:
    live = c0 > 0.0                                            # no (…, K) float64 temporaries
    c0_live = c0[live]
    offsets = np.zeros(k, np.float64)
    slots = np.empty(coeffs.shape, np.float32)
    slots[..., 0] = c0
    for j in range(1, k):
        cj = coeffs[..., j].astype(np.float64)
        if c0_live.size:
            offsets[j] = max(0.0, float((-cj[live] / c0_live).max()))
        cj += offsets[j] * c0
        slots[..., j] = np.maximum(cj, 0.0)
    return slots, offsets


def bake_atlas(table, path: str | os.PathLike, wavelengths_nm: np.ndarray | None = None,
               n_phi_d: int = N_PHI_D, tolerance: float = DEFAULT_TOLERANCE,
               max_coeffs: int | None = None, overwrite: bool = True,
               progress: Callable[[float], None] | None = None,
               cancel: Callable[[], bool] | None = None) -> AtlasInfo:
    """Write the coefficient atlas of a spectral :class:`~specgen_addon.brdf.table.BRDFTable`.

    Parameters
    ----------
    table
        Spectral BRDF table (values in sr⁻¹ on the MERL grid).
    path
        Base name ``….exr``; group ``g`` goes to :func:`group_path` (tiled float32 RGBA EXR).
    wavelengths_nm
        Bands (nm) the render will output; the table is interpolated linearly in λ. Defaults to
        the table's own.
    n_phi_d
        φd samples kept (lookup resolution): 180 is the full MERL grid.
    tolerance, max_coeffs
        Spectral basis truncation (see :func:`spectral_basis`); ``tolerance=0`` keeps it exact.

    The native closure fit (:func:`specgen_addon.bake.closure_fit.fit_closures`) at the same bands is stored
    in the returned info.
    """
    if not getattr(table, "is_spectral", False):
        raise SpecGenError("the Blender bake needs a spectral BRDF table (wavelengths in nm)")
    if not (isinstance(tolerance, (int, float, np.floating)) and 0.0 <= tolerance <= 1.0):
        raise SpecGenError(f"tolerance must be a number between 0 and 1, got {tolerance!r}")
    if max_coeffs is not None and not (isinstance(max_coeffs, (int, np.integer)) and max_coeffs >= 1):
        raise SpecGenError(f"max_coeffs must be a whole number ≥ 1, got {max_coeffs!r}")
    check_output_dir(Path(path).parent)   # a file in the way: refused before the work
    wl = np.asarray(table.wavelengths if wavelengths_nm is None else wavelengths_nm, dtype=np.float64)
    # the closure fit only reads the table: it runs on a second thread beside the basis
    with ThreadPoolExecutor(max_workers=1) as pool:
        closures = pool.submit(_fit_standins, table, None if wavelengths_nm is None else wl)
        values = table.values
        if wavelengths_nm is not None:
            weights = table.wavelength_weights(wl).astype(np.float32)       # (C, Λ)
            values = np.tensordot(values, weights, axes=([3], [0]))
        values = resample_phi_d(np.maximum(values, 0.0), n_phi_d).astype(np.float32)  # (90, 90, P, Λ)
        basis, rel = spectral_basis(values, tolerance, max_coeffs, reachable=reachable_entries(n_phi_d))
        if progress is not None:
            progress(0.2)
        slots, offsets = shifted_coefficients(values @ basis.T.astype(np.float32))  # (90, 90, P, K)
        tiles_x, tiles_y = atlas_layout(n_phi_d)
        info = AtlasInfo(Path(path), wl, basis, offsets, n_phi_d, tiles_x, tiles_y, rel, closures.result())
    make_output_dir(info.path.parent)
    shape = (tiles_y * N_THETA_D, tiles_x * N_THETA_H)
    for g, target in enumerate(info.group_paths):
        if cancel is not None and cancel():
            raise Cancelled("bake cancelled")
        channels = {}
        for c, name in enumerate("RGBA"):
            slot = COEFFS_PER_RENDER * g + c
            plane = np.zeros(shape, np.float32)
            if slot < slots.shape[-1]:
                # tile k at column k % tiles_x, row k // tiles_x; inside it x = θh index, y = θd.
                tiles = slots[:, :, :, slot].transpose(2, 1, 0)         # (P, θd, θh)
                plane[:] = tiles.reshape(tiles_y, tiles_x, N_THETA_D, N_THETA_H) \
                    .transpose(0, 2, 1, 3).reshape(shape)
            channels[name] = plane
        attrs = {"specgenSlots": f"{COEFFS_PER_RENDER * g}-{COEFFS_PER_RENDER * g + 3}",
                 "specgenPhiD": str(n_phi_d)}
        _write_exr(target, channels, overwrite=overwrite, attributes=attrs, tiled=True)
        if progress is not None:
            progress(0.2 + 0.8 * (g + 1) / info.n_renders)
    return info


def atlas_lookup_reference(atlas: np.ndarray, info: AtlasInfo, theta_h: np.ndarray,
                           theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
    """NumPy twin of the shader's lookup on :func:`read_atlas` (two bilinear taps), projected back
    onto the bands with the basis: ``f_r`` (N, Λ)."""
    x = np.clip(theta_h_index(np.ravel(theta_h)), 0, N_THETA_H - 1)
    y = np.clip(theta_d_index(np.ravel(theta_d)), 0, N_THETA_D - 1)
    kf = phi_d_index(np.ravel(phi_d)) * info.n_phi_d / N_PHI_D
    k0 = np.floor(kf).astype(int) % info.n_phi_d
    k1 = (k0 + 1) % info.n_phi_d
    tk = (kf - np.floor(kf))[:, None]

    def bilinear(k: np.ndarray) -> np.ndarray:
        ox = (k % info.tiles_x) * N_THETA_H
        oy = (k // info.tiles_x) * N_THETA_D
        x0 = np.minimum(np.floor(x), N_THETA_H - 2).astype(int)
        y0 = np.minimum(np.floor(y), N_THETA_D - 2).astype(int)
        tx, ty = (x - x0)[:, None], (y - y0)[:, None]
        a = atlas[oy + y0, ox + x0]
        b = atlas[oy + y0, ox + x0 + 1]
        c = atlas[oy + y0 + 1, ox + x0]
        d = atlas[oy + y0 + 1, ox + x0 + 1]
        return (1 - ty) * ((1 - tx) * a + tx * b) + ty * ((1 - tx) * c + tx * d)

    slots = (1 - tk) * bilinear(k0) + tk * bilinear(k1)
    coeffs = slots[:, :info.n_slots] - slots[:, :1] * info.offsets[None]
    return coeffs @ info.basis


def read_atlas(info: AtlasInfo) -> np.ndarray:
    """All slot planes stacked (H, W, 4 × groups) (for tests and checks)."""
    planes = []
    for p in info.group_paths:
        ch, _ = read_exr(p)
        planes += [ch[c] for c in "RGBA"]
    return np.stack(planes, axis=-1)


def assemble_spectrum(images: np.ndarray, basis: np.ndarray, offsets: np.ndarray,
                      uplift: np.ndarray) -> np.ndarray:
    """Spectral radiance (H, W, Λ) from the rendered slot images.

    ``images`` (H, W, S ≥ K, 3): slot s lit by the R, G, B parts of the lighting; ``basis`` (K, Λ)
    = ``B_k(λ)``; ``offsets`` (K,) = ``o_k`` (``o_0 = 0``); ``uplift`` (3, Λ) = ``U_c(λ)``.
    ``L(λ) = Σ_c Σ_k U_c(λ) B_k(λ) (I'_{c,k} − o_k I'_{c,0})``.
    """
    k = basis.shape[0]
    coeff = images[:, :, :k, :].astype(np.float64) - \
        np.asarray(offsets, np.float64)[None, None, :, None] * images[:, :, :1, :].astype(np.float64)
    return np.einsum("hwkc,cl,kl->hwl", coeff, uplift, basis, optimize=True).astype(np.float32)


# ---------------------------------------------------------------------------------- lighting
@dataclass
class Light:
    """A light the shader evaluates.

    ``kind`` is ``"sun"`` (``vector`` = world direction towards the light, ``rgb`` = linear-sRGB
    irradiance on a surface facing it, W·m⁻²) or ``"point"`` (``vector`` = world position,
    ``rgb`` = radiant intensity, W·sr⁻¹). Spectra follow as ``rgb @ U`` (module docstring).
    """

    kind: str
    vector: tuple[float, float, float]
    rgb: tuple[float, float, float]


@dataclass
class EnvironmentLight:
    """An equirect environment: linear-sRGB radiance (H, W, 3), row 0 at the zenith, Blender's
    mapping (``u = −atan2(y, x)/2π + ½``, ``v = asin(z)/π + ½``)."""

    rgb: np.ndarray
    n_list: int = 4096
    seed: int = 0


@dataclass
class SceneLights:
    """Everything the shader needs to light one scene."""

    lights: list[Light] = field(default_factory=list)
    environment: EnvironmentLight | None = None


def light_socket_values(light: Light | None) -> dict[str, object]:
    """Socket values of one shader light slot: ``Kind`` (0 off, 1 sun, 2 point), ``Vec``, ``Color``."""
    if light is None:
        return {"Kind": 0, "Vec": (0.0, 0.0, 0.0), "Color": (0.0, 0.0, 0.0, 1.0)}
    if light.kind not in ("sun", "point"):
        raise SpecGenError(f"unsupported light kind {light.kind!r} (sun and point are supported)")
    return {"Kind": 1 if light.kind == "sun" else 2, "Vec": tuple(float(c) for c in light.vector),
            "Color": (*(float(c) for c in light.rgb), 1.0)}


def environment_density(rgb: np.ndarray) -> np.ndarray:
    """Texel probabilities ∝ luminance · cos(elevation) (sum 1), as the reference renderer samples."""
    h = rgb.shape[0]
    cos_el = np.cos(((1.0 - (np.arange(h) + 0.5) / h) - 0.5) * np.pi)
    weight = np.clip(rgb @ srgb_luminance_weights(), 0, None) * cos_el[:, None]
    if weight.sum() <= 0:
        weight = np.ones_like(weight) * cos_el[:, None]
    return weight / weight.sum()


def uv_to_blender_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Equirect (u, v) (v = 0 at the nadir) → Blender world directions, inverse of Blender's
    ``direction_to_equirectangular``."""
    phi = -(u - 0.5) * 2.0 * np.pi
    el = (v - 0.5) * np.pi
    return np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], axis=-1)


def bake_environment(env: EnvironmentLight, map_path: str | os.PathLike,
                     list_path: str | os.PathLike) -> tuple[Path, Path]:
    """Write the environment map (RGB radiance, A = density factor) and the sample-direction list.

    Alpha stores ``p_texel · H · W / (2π²)``; the shader divides by ``cos(elevation)`` to get the
    solid-angle density (sr⁻¹) of the luminance sampling. The list holds ``n_list`` directions drawn
    from that density (stratified in texel probability, jittered in the texel), RGBA =
    ``(x, y, z, 0)``, ``ENV_LIST_WIDTH`` per row.
    """
    rgb = np.asarray(env.rgb, dtype=np.float32)
    h, w = rgb.shape[:2]
    p = environment_density(rgb)
    alpha = p * (h * w) / (2.0 * np.pi ** 2)
    _write_exr(Path(map_path), {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2], "A": alpha})
    rng = np.random.default_rng(env.seed)
    n = int(env.n_list)
    n = -(-n // ENV_LIST_WIDTH) * ENV_LIST_WIDTH
    cdf = np.cumsum(p.ravel())
    cdf /= cdf[-1]
    idx = np.minimum(np.searchsorted(cdf, (np.arange(n) + rng.random(n)) / n, side="right"), h * w - 1)
    row, col = np.divmod(idx, w)
    u = (col + rng.random(n)) / w
    v = 1.0 - (row + rng.random(n)) / h
    d = uv_to_blender_direction(u, v).reshape(n // ENV_LIST_WIDTH, ENV_LIST_WIDTH, 3)
    _write_exr(Path(list_path), {"R": d[..., 0], "G": d[..., 1], "B": d[..., 2],
                                 "A": np.zeros(d.shape[:2], np.float32)})
    return Path(map_path), Path(list_path)


# ---------------------------------------------------------------------------------- files
def save_atlas_info(info: AtlasInfo, path: str | os.PathLike) -> Path:
    """Write the atlas description (JSON beside the textures) so a later session can apply it."""
    import json

    data = {"format": "specgen-atlas", "version": ATLAS_VERSION, "path": str(info.path),
            "wavelengths_nm": [float(w) for w in info.wavelengths_nm],
            "basis": info.basis.tolist(), "offsets": info.offsets.tolist(), "n_phi_d": info.n_phi_d, "tiles_x": info.tiles_x,
            "tiles_y": info.tiles_y, "rel_error": info.rel_error,
            "closures": None if info.closures is None else info.closures.to_json()}
    with atomic_write(path, overwrite=True) as tmp:
        tmp.write_text(json.dumps(data))
    return Path(path)


def set_atlas_path(path: str | os.PathLike, atlas: str | os.PathLike) -> None:
    """Point :func:`save_atlas_info`'s JSON at ``path`` to the textures of ``atlas`` (its files
    moved, or renamed with their set)."""
    import json

    path = Path(path)
    try:
        data = json.loads(path.read_text())
        data["path"] = str(atlas)
    except (OSError, ValueError, TypeError) as exc:
        raise SpecGenError(f"{path}: cannot read the baked lookup description ({exc})") from None
    with atomic_write(path, overwrite=True) as tmp:
        tmp.write_text(json.dumps(data))


def load_atlas_info(path: str | os.PathLike) -> AtlasInfo:
    """Read :func:`save_atlas_info`'s JSON; SpecGenError if missing, corrupt or incomplete.

    The JSON holds the textures' absolute path as baked; when the folder has moved since (with its
    .blend, to another machine), the textures are those beside the JSON, under the same names."""
    import json

    path = Path(path)
    try:
        data = json.loads(path.read_text())
        if data.get("format") != "specgen-atlas":
            raise ValueError("not a SpecGen atlas description")
        if data.get("version") != ATLAS_VERSION:
            raise ValueError(f"baked by an older SpecGen (format {data.get('version')}); generate it again")
        info = AtlasInfo(Path(data["path"]), np.asarray(data["wavelengths_nm"], float),
                         np.asarray(data["basis"], float), np.asarray(data["offsets"], float),
                         int(data["n_phi_d"]), int(data["tiles_x"]),
                         int(data["tiles_y"]), float(data["rel_error"]))
        if data.get("closures"):
            info.closures = ClosureFit.from_json(data["closures"])
    except (OSError, ValueError, KeyError, TypeError, SpecGenError) as exc:
        raise SpecGenError(f"{path}: cannot read the baked lookup description ({exc})") from None
    if not all(p.is_file() for p in info.group_paths):
        # the folder moved (the textures came with it), perhaps from another system: a Windows
        # path's name is found whichever separator the stored path uses
        beside = path.parent / PureWindowsPath(data["path"]).name
        if all(p.is_file() for p in group_paths_of(beside, info.n_renders)):
            info.path = beside
    missing = [str(p) for p in info.group_paths if not p.is_file()]
    if missing:
        raise SpecGenError(f"{path}: baked lookup textures are missing ({missing[0]})")
    return info


def check_lookup_outputs(out_dir: str | os.PathLike, name: str, overwrite: bool) -> Path:
    """Refuse up front what :func:`bake_lookup` could not write: a bad ``name``, an output folder
    that is a file or not writable, or (without ``overwrite``) existing outputs of ``name``."""
    out = Path(out_dir)
    safe_name(name, "BRDF name")
    check_output_dir(out)
    if not overwrite:
        existing = [p for p in (out / f"{name}.npz", out / f"{name}_lookup.json") if p.exists()]
        existing += sorted(out.glob(f"{name}_lookup.g*.exr"))
        if existing:
            raise OutputExistsError(f"{existing[0]}: already exists (turn on Overwrite to replace it)")
    return out


def bake_lookup(table, out: Path, name: str, n_phi_d: int = N_PHI_D,
                tolerance: float = DEFAULT_TOLERANCE, save_table: bool = False, preview: bool = False,
                progress: Callable[[float], None] | None = None,
                cancel: Callable[[], bool] | None = None) -> AtlasInfo:
    """Everything Blender reads of one spectral table, in ``out``: the coefficient atlas and its
    JSON (``<name>_lookup.*``), with ``save_table`` the compact material file ``<name>.npz``
    (:mod:`specgen_addon.brdf.material_file`), with ``preview`` ``<name>_preview.png``
    (:mod:`specgen_addon.bake.preview`). Outputs are replaced; check them first with
    :func:`check_lookup_outputs`. The material file is written on a thread of its own beside the
    bake (its encoding and deflate release the GIL); leaving the executor waits for it, so it is
    finished before this returns or fails (nothing still writes when a failure cleans up)."""
    with ThreadPoolExecutor(max_workers=1) as writer:
        saved = writer.submit(table.save, out / f"{name}.npz", overwrite=True, compact=True) \
            if save_table else None
        if preview:
            write_preview(table, out / f"{name}_preview.png")
        info = bake_atlas(table, out / f"{name}_lookup.exr", n_phi_d=n_phi_d, tolerance=tolerance,
                          progress=progress, cancel=cancel)
        save_atlas_info(info, out / f"{name}_lookup.json")
        if saved is not None:
            saved.result()               # its error, if any
    return info
