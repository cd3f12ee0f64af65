"""Bake a spectral BRDF table and a scene's lighting into the textures the OSL shader reads.

Three files, all float32 OpenEXR, no ``bpy`` here (the Blender side only fills in
:class:`SceneLights` from the scene):

* **BRDF atlas** (:func:`bake_atlas`): the MERL-grid table ``f_r(θh, θd, φd, λ)`` (sr⁻¹) laid out
  as one 90×90 tile per ``φd`` sample (x = √-warped ``θh`` index, y = ``θd`` index), tiles in
  row-major order, ``4·G`` channels ``b000, b001, …`` holding the bands in groups of four. The
  shader does the table's trilinear interpolation (:meth:`specgen_addon.table.BRDFTable.eval_hd`)
  with two bilinear lookups per group of four bands (one per neighbouring ``φd`` tile).
* **Light table** (:func:`bake_light_table`): one row per light (sun or point) with its position
  or direction and its spectral irradiance / intensity per group, plus one row holding the
  environment's RGB → spectrum matrix (Mallett & Yuksel 2019 basis × D65, as the reference
  renderer uplifts environment texels).
* **Environment** (:func:`bake_environment`): the equirect radiance (RGB) with its importance
  sampling density in the alpha channel, and a list of directions drawn from that density.

Wavelengths are nanometres, angles radians, directions are Blender world vectors (z up).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..specgen_addon.errors import Cancelled, SpecGenError
from ..specgen_addon.io_utils import atomic_write
from ..specgen_addon.table import N_PHI_D, N_THETA_D, N_THETA_H, grid_angles

BANDS_PER_GROUP = 4
#: Bands one Cycles render carries: 4 colour passes (Emission, Diffuse/Glossy/Transmission Color)
#: × 3 channels, i.e. three groups of four.
GROUPS_PER_RENDER = 3
BANDS_PER_RENDER = BANDS_PER_GROUP * GROUPS_PER_RENDER
LIGHT_SUN = 0.0
LIGHT_POINT = 1.0
ENV_LIST_WIDTH = 256


def _write_exr(path: Path, channels: dict[str, np.ndarray], overwrite: bool = True,
               attributes: dict[str, str] | None = None) -> Path:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update(attributes or {})
    with atomic_write(path, overwrite=overwrite) as tmp:
        with OpenEXR.File(header, {k: np.ascontiguousarray(v, dtype=np.float32)
                                   for k, v in channels.items()}) as exr:
            exr.write(str(tmp))
    return Path(path)


def n_groups(n_bands: int) -> int:
    """Groups of four bands needed for ``n_bands``."""
    return -(-int(n_bands) // BANDS_PER_GROUP)


def n_renders(n_bands: int) -> int:
    """Cycles renders needed for ``n_bands`` (12 bands per render)."""
    return -(-n_groups(n_bands) // GROUPS_PER_RENDER)


def band_channel(index: int) -> str:
    """Atlas channel name of band ``index`` (sorts in band order, as EXR stores channels)."""
    return f"b{index:03d}"


@dataclass
class AtlasInfo:
    """What :func:`bake_atlas` wrote: file, tile layout and the bands (nm) in channel order."""

    path: Path
    wavelengths_nm: np.ndarray
    n_phi_d: int
    tiles_x: int
    tiles_y: int

    @property
    def n_groups(self) -> int:
        return n_groups(self.wavelengths_nm.size)


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


def bake_atlas(table, path: str | os.PathLike, wavelengths_nm: np.ndarray | None = None,
               n_phi_d: int = N_PHI_D, overwrite: bool = True,
               progress: Callable[[float], None] | None = None,
               cancel: Callable[[], bool] | None = None) -> AtlasInfo:
    """Write the per-wavelength lookup atlas of a spectral :class:`~specgen_addon.table.BRDFTable`.

    Parameters
    ----------
    table
        Spectral BRDF table (values in sr⁻¹ on the MERL grid).
    path
        Target ``.exr``.
    wavelengths_nm
        Bands to bake (nm); the table is interpolated linearly in λ. Defaults to the table's own.
    n_phi_d
        φd samples kept (lookup resolution): 180 is the full MERL grid.
    """
    if not getattr(table, "is_spectral", False):
        raise SpecGenError("the Blender bake needs a spectral BRDF table (wavelengths in nm)")
    wl = np.asarray(table.wavelengths if wavelengths_nm is None else wavelengths_nm, dtype=np.float64)
    values = table.values
    if wavelengths_nm is not None:
        weights = table.wavelength_weights(wl).astype(np.float32)       # (C, Λ)
        values = np.tensordot(values, weights, axes=([3], [0]))
    values = resample_phi_d(np.maximum(values, 0.0), n_phi_d)           # (90, 90, P, Λ)
    tiles_x, tiles_y = atlas_layout(n_phi_d)
    g = n_groups(wl.size)
    channels: dict[str, np.ndarray] = {}
    for band in range(g * BANDS_PER_GROUP):
        if cancel is not None and cancel():
            raise Cancelled("bake cancelled")
        plane = np.zeros((tiles_y * N_THETA_D, tiles_x * N_THETA_H), np.float32)
        if band < wl.size:
            # tile k sits at column k % tiles_x, row k // tiles_x; inside it x = θh index, y = θd.
            tiles = values[:, :, :, band].transpose(2, 1, 0)             # (P, θd, θh)
            plane[:] = tiles.reshape(tiles_y, tiles_x, N_THETA_D, N_THETA_H) \
                .transpose(0, 2, 1, 3).reshape(plane.shape)
        channels[band_channel(band)] = plane
        if progress is not None:
            progress(0.9 * (band + 1) / (g * BANDS_PER_GROUP))
    attrs = {"specgenWavelengthsNm": ",".join(f"{w:g}" for w in wl), "specgenPhiD": str(n_phi_d)}
    _write_exr(Path(path), channels, overwrite=overwrite, attributes=attrs)
    if progress is not None:
        progress(1.0)
    return AtlasInfo(Path(path), wl, n_phi_d, tiles_x, tiles_y)


def atlas_lookup_reference(atlas: np.ndarray, info: AtlasInfo, theta_h: np.ndarray,
                           theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
    """NumPy twin of the shader's lookup (two bilinear taps per band), for tests: (N, Λ)."""
    from ..specgen_addon.table import phi_d_index, theta_d_index, theta_h_index

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

    return ((1 - tk) * bilinear(k0) + tk * bilinear(k1))[:, :info.wavelengths_nm.size]


def read_atlas(path: str | os.PathLike) -> np.ndarray:
    """Atlas planes stacked (H, W, 4G), band order (for tests and checks)."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as exr:
        ch = exr.parts[0].channels
        return np.stack([np.asarray(ch[k].pixels) for k in sorted(ch)], axis=-1)


# ---------------------------------------------------------------------------------- lighting
@dataclass
class Light:
    """A light the shader loops over.

    ``kind`` is ``"sun"`` (``vector`` = world direction towards the light, ``spectrum`` = irradiance
    E(λ) in W·m⁻²·nm⁻¹ on a surface facing it) or ``"point"`` (``vector`` = world position,
    ``spectrum`` = radiant intensity I(λ) in W·sr⁻¹·nm⁻¹).
    """

    kind: str
    vector: tuple[float, float, float]
    spectrum: np.ndarray


@dataclass
class EnvironmentLight:
    """An equirect environment: linear-sRGB radiance (H, W, 3), row 0 at the zenith, Blender's
    mapping (``u = −atan2(y, x)/2π + ½``, ``v = asin(z)/π + ½``), uplifted to spectra with ``basis``
    (3, Λ): ``L(λ) = rgb @ basis``."""

    rgb: np.ndarray
    basis: np.ndarray
    n_list: int = 4096
    seed: int = 0


@dataclass
class SceneLights:
    """Everything the shader needs to light one scene at the baked bands."""

    wavelengths_nm: np.ndarray
    lights: list[Light] = field(default_factory=list)
    environment: EnvironmentLight | None = None


def bake_light_table(scene: SceneLights, path: str | os.PathLike) -> Path:
    """Write the light table: row per light, then the environment's uplift row.

    Pixel 0 of a light row is ``(kind, x, y, z)``; pixel ``1 + g`` its spectrum for bands
    ``4g … 4g+3``. In the environment row (index ``len(lights)``) pixel ``1 + 3g + c`` holds row
    ``c`` (R, G, B) of the uplift matrix for group ``g``.
    """
    wl = np.asarray(scene.wavelengths_nm, dtype=np.float64)
    g = n_groups(wl.size)
    padded = g * BANDS_PER_GROUP
    width = 1 + 3 * g
    rows = len(scene.lights) + 1
    pixels = np.zeros((rows, width, 4), np.float32)
    for r, light in enumerate(scene.lights):
        if light.kind not in ("sun", "point"):
            raise SpecGenError(f"unsupported light kind {light.kind!r} (sun and point are supported)")
        spectrum = np.zeros(padded)
        spectrum[:wl.size] = np.asarray(light.spectrum, dtype=np.float64)
        pixels[r, 0] = (LIGHT_SUN if light.kind == "sun" else LIGHT_POINT, *light.vector)
        pixels[r, 1:1 + g] = spectrum.reshape(g, BANDS_PER_GROUP)
    if scene.environment is not None:
        basis = np.zeros((3, padded))
        basis[:, :wl.size] = scene.environment.basis
        for grp in range(g):
            for c in range(3):
                pixels[-1, 1 + 3 * grp + c] = basis[c, BANDS_PER_GROUP * grp:BANDS_PER_GROUP * (grp + 1)]
    channels = {name: pixels[..., i] for i, name in enumerate("RGBA")}
    return _write_exr(Path(path), channels)


def environment_density(rgb: np.ndarray) -> np.ndarray:
    """Texel probabilities ∝ luminance · cos(elevation) (sum 1), as the reference renderer samples."""
    from ..specgen_addon.render.environment import srgb_luminance_weights

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
