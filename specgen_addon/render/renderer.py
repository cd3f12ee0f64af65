"""Reference spectral renderer: any BRDF on a normal map, lit by distant lights and an environment.

Per pixel with normal ``n`` and outgoing direction ``ω_o`` (towards the camera) the reflected
radiance is the rendering equation without interreflection or shadowing (convex geometry):

    L(λ) = Σ_lights f_r(ω_l, ω_o, λ) E_l S_l(λ) (n·ω_l)⁺  +  ∫_Ω f_r(ω_i, ω_o, λ) L_env(ω_i, λ) (n·ω_i)⁺ dω_i

Distant lights are evaluated exactly; the environment integral by multiple importance sampling with
a control variate (:mod:`specgen_addon.render.sampling`). A :class:`Scene` holds everything that does
not depend on the BRDF (shading frames, light directions, environment samples and their weights),
so rendering many materials under one lighting costs one batch of BRDF evaluations each.

BRDFs follow the project protocol: ``eval(wi, wo, λ) -> (N, Λ)`` (spectral) or
``eval_rgb(wi, wo) -> (N, 3)`` (linear sRGB), sr⁻¹, local frame with the normal on +z.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.environment import Environment
from specgen_addon.render.geometry import Geometry, shading_frame, to_local
from specgen_addon.render.lights import DistantLight
from specgen_addon.render.sampling import EnvSampler, EnvSampling, SampleBlock, diffuse_floor

ProgressFn = Callable[[float], None]


class SpectralBRDF(Protocol):
    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray: ...


class RGBBRDF(Protocol):
    def eval_rgb(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray: ...


@dataclass
class RenderResult:
    """A rendered image.

    ``spectral`` is radiance (H, W, Λ) at ``wavelengths_nm`` (``None`` for RGB renders); ``rgb`` is
    linear sRGB (H, W, 3) (``None`` if the grid has no visible band); ``mask`` the covered pixels.
    """

    rgb: np.ndarray | None
    mask: np.ndarray
    spectral: np.ndarray | None = None
    wavelengths_nm: np.ndarray | None = None
    info: dict = field(default_factory=dict)


@dataclass
class _Block:
    ids: np.ndarray                 # flat pixel indices (P,)
    wo_local: np.ndarray            # (P, 3)
    light_wi: list[np.ndarray]      # per light (P, 3) local incident direction
    env: SampleBlock | None
    has_samples: np.ndarray | None = None      # (P,) bool: pixel has ≥ 1 environment sample
    segment_starts: np.ndarray | None = None   # first sample row of each such pixel


class Scene:
    """Geometry + camera + lighting, prepared once and rendered for any number of BRDFs.

    Parameters
    ----------
    geometry
        Normal map and mask (e.g. :func:`~specgen_addon.render.geometry.sphere_geometry`).
    lights
        Distant lights (exact).
    environment
        Equirect environment (importance sampled), or ``None``.
    camera_dir
        World direction towards the camera; defaults to ``geometry.view_dir``.
    sampling
        Environment sample counts, MIS heuristic, control variate and seed.
    """

    def __init__(self, geometry: Geometry, lights: Sequence[DistantLight] = (),
                 environment: Environment | None = None, camera_dir: Sequence[float] | None = None,
                 sampling: EnvSampling = EnvSampling()):
        if not lights and environment is None:
            raise SpecGenError("render needs at least one distant light or an environment")
        self.geometry = geometry
        self.lights = list(lights)
        self.environment = environment
        self.sampling = sampling
        d = geometry.view_dir if camera_dir is None else np.asarray(camera_dir, dtype=np.float64)
        norm = np.linalg.norm(d)
        if not np.isfinite(norm) or norm == 0:
            raise SpecGenError(f"camera direction {camera_dir} is not a valid vector")
        self.camera_dir = d / norm
        self._blocks: list[_Block] | None = None

    def with_sampling(self, sampling: EnvSampling) -> "Scene":
        """The same geometry, lights, environment and camera with other environment samples (a new,
        unprepared scene): e.g. a photo that shares none of the refinement operator's samples."""
        return Scene(self.geometry, self.lights, self.environment, camera_dir=self.camera_dir,
                     sampling=sampling)

    def _prepare(self, progress: ProgressFn | None = None) -> list[_Block]:
        if self._blocks is not None:
            return self._blocks
        h, w = self.geometry.shape
        normals = self.geometry.normals.reshape(-1, 3)
        visible = self.geometry.mask.reshape(-1) & (normals @ self.camera_dir > 0)
        ids = np.flatnonzero(visible)
        sampler = None if self.environment is None else EnvSampler(self.environment, self.sampling, h * w)
        light_dirs = [l.unit_direction() for l in self.lights]
        blocks = []
        chunk = self.sampling.chunk_pixels
        for start in range(0, ids.size, chunk):
            sel = ids[start:start + chunk]
            n = normals[sel]
            t, b = shading_frame(n)
            wo_l = to_local(np.broadcast_to(self.camera_dir, n.shape), t, b, n)
            light_wi = [to_local(np.broadcast_to(ld, n.shape), t, b, n) for ld in light_dirs]
            env = None if sampler is None else sampler.block(n, t, b, self.camera_dir, sel)
            if env is not None:  # float32 storage halves memory; BRDFs get float64
                env = SampleBlock(env.pixel, env.wi_local.astype(np.float32),
                                  env.weight_rgb.astype(np.float32), env.irradiance_rgb)
            blk = _Block(sel, wo_l, light_wi, env)
            if env is not None:
                counts = np.bincount(env.pixel, minlength=sel.size)
                if np.any(np.diff(env.pixel) < 0):
                    raise SpecGenError("internal: environment samples are not grouped by pixel")
                blk.has_samples = counts > 0
                blk.segment_starts = (np.cumsum(counts) - counts)[blk.has_samples]
            blocks.append(blk)
            if progress is not None:
                progress(0.5 * min(1.0, (start + chunk) / max(ids.size, 1)))
        self._blocks = blocks
        return blocks

    def _render(self, eval_fn: Callable[[np.ndarray, np.ndarray], np.ndarray], n_channels: int,
                light_spectra: list[np.ndarray], env_to_channels: np.ndarray | None,
                progress: ProgressFn | None) -> np.ndarray:
        def evaluate(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            out = np.asarray(eval_fn(np.asarray(wi, np.float64), np.asarray(wo, np.float64)),
                             dtype=np.float64)
            if out.shape != (wi.shape[0], n_channels):
                raise SpecGenError(f"BRDF returned shape {out.shape}, expected {(wi.shape[0], n_channels)}")
            return out

        blocks = self._prepare(progress)
        use_cv = self.environment is not None and self.sampling.control_variate
        floor = diffuse_floor(evaluate) if use_cv else None
        h, w = self.geometry.shape
        image = np.zeros((h * w, n_channels))
        for i, blk in enumerate(blocks):
            out = np.zeros((blk.ids.size, n_channels))
            for wi_l, spectrum in zip(blk.light_wi, light_spectra):
                lit = wi_l[:, 2] > 0
                if np.any(lit):
                    out[lit] += evaluate(wi_l[lit], blk.wo_local[lit]) * (spectrum * wi_l[lit, 2:3])
            if blk.env is not None and blk.segment_starts.size:
                e = blk.env
                fr = evaluate(e.wi_local, blk.wo_local[e.pixel])
                radiance = e.weight_rgb.astype(np.float64)
                if env_to_channels is not None:
                    radiance = radiance @ env_to_channels
                if floor is not None:  # control variate: ∫ c L cos dω = c · E(n) exactly
                    fr -= floor
                    irradiance = e.irradiance_rgb if env_to_channels is None else e.irradiance_rgb @ env_to_channels
                    out += floor * irradiance
                fr *= radiance
                # samples are grouped by pixel in ascending order: one segmented sum
                out[blk.has_samples] += np.add.reduceat(fr, blk.segment_starts, axis=0)
            image[blk.ids] = out
            if progress is not None:
                progress(0.5 + 0.5 * (i + 1) / len(blocks))
        return image.reshape(h, w, n_channels)

    def render_spectral(self, brdf: SpectralBRDF,
                        wavelengths_nm: np.ndarray = spectra.DEFAULT_WAVELENGTHS_NM,
                        progress: ProgressFn | None = None) -> RenderResult:
        """Spectral radiance (H, W, Λ) of ``brdf`` and its linear sRGB through the CIE 1931 CMFs.

        ``rgb`` is :func:`specgen_addon.spectral.spectra.spectral_to_linear_srgb` (white-balanced to D65), or
        ``None`` if the grid has no visible band.
        """
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        env_u = None if self.environment is None else self.environment.spectral_basis(wl)
        image = self._render(lambda wi, wo: brdf.eval(wi, wo, wl), wl.size,
                             [l.spectrum(wl) for l in self.lights], env_u, progress)
        try:
            rgb = spectra.spectral_to_linear_srgb(image, wl)
        except SpecGenError:  # e.g. a near-infrared-only grid
            rgb = None
        return RenderResult(rgb=rgb, mask=self.geometry.mask.copy(), spectral=image,
                            wavelengths_nm=wl, info=self._info())

    def render_rgb(self, brdf: RGBBRDF, progress: ProgressFn | None = None) -> RenderResult:
        """Linear-sRGB image of an RGB BRDF (``brdf.eval_rgb(wi, wo) -> (N, 3)``).

        Lights enter as their spectrum's linear sRGB (:meth:`DistantLight.rgb`), environment texels
        as they are.
        """
        if not hasattr(brdf, "eval_rgb"):
            raise SpecGenError(f"{type(brdf).__name__} has no eval_rgb; render it with render_spectral")
        image = self._render(brdf.eval_rgb, 3, [l.rgb() for l in self.lights], None, progress)
        return RenderResult(rgb=image, mask=self.geometry.mask.copy(), info=self._info())

    def _info(self) -> dict:
        return {"samples_per_pixel": self.sampling.total if self.environment is not None else 0,
                "lights": len(self.lights),
                "environment": None if self.environment is None else self.environment.name}


#: Prepared scenes of recent one-shot calls, keyed by content (a GT and a prediction rendered one
#: after the other under the same lighting share the preparation).
_SCENE_CACHE: dict[str, Scene] = {}
_SCENE_CACHE_SIZE = 2


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _cached_scene(geometry: Geometry, lights: Sequence[DistantLight], environment: Environment | None,
                  camera_dir: Sequence[float] | None, sampling: EnvSampling) -> Scene:
    env_key = None if environment is None else (
        _digest(environment.rgb), environment.rotation_rad, environment.uplift)
    key = repr((_digest(geometry.normals, geometry.mask, geometry.view_dir), tuple(lights), env_key,
                None if camera_dir is None else tuple(np.asarray(camera_dir, float)), sampling))
    scene = _SCENE_CACHE.pop(key, None)
    if scene is None:
        scene = Scene(geometry, lights, environment, camera_dir, sampling)
    _SCENE_CACHE[key] = scene  # most recent last
    while len(_SCENE_CACHE) > _SCENE_CACHE_SIZE:
        _SCENE_CACHE.pop(next(iter(_SCENE_CACHE)))
    return scene


def render_spectral(brdf: SpectralBRDF, geometry: Geometry, *, lights: Sequence[DistantLight] = (),
                    environment: Environment | None = None,
                    wavelengths_nm: np.ndarray = spectra.DEFAULT_WAVELENGTHS_NM,
                    camera_dir: Sequence[float] | None = None,
                    sampling: EnvSampling = EnvSampling(),
                    progress: ProgressFn | None = None) -> RenderResult:
    """Spectral image (H, W, Λ) of ``brdf`` on ``geometry`` plus its linear sRGB (one-shot
    :class:`Scene`, reused from the last two calls with identical geometry and lighting)."""
    return _cached_scene(geometry, lights, environment, camera_dir, sampling).render_spectral(
        brdf, wavelengths_nm, progress)


def render_rgb(brdf: RGBBRDF, geometry: Geometry, *, lights: Sequence[DistantLight] = (),
               environment: Environment | None = None, camera_dir: Sequence[float] | None = None,
               sampling: EnvSampling = EnvSampling(),
               progress: ProgressFn | None = None) -> RenderResult:
    """Linear-sRGB image of an RGB BRDF (``eval_rgb``) on ``geometry`` (see :func:`render_spectral`)."""
    return _cached_scene(geometry, lights, environment, camera_dir, sampling).render_rgb(brdf, progress)
