"""Environment-integral sampling: directions and MIS weights per pixel, independent of the BRDF.

The environment term ``∫_Ω f_r(ω_i, ω_o, λ) L_env(ω_i, λ) (n·ω_i)⁺ dω_i`` is estimated by multiple
importance sampling (Veach 1997, §9.2, multi-sample model) with ``n_k`` directions from each of:

* the environment's luminance distribution (:meth:`Environment.sample`);
* a cosine-weighted hemisphere about ``n``;
* power-cosine lobes ``(e+1)/2π · cos^e`` about the mirror direction, for several exponents ``e``
  (covering matte to near-mirror GGX without knowing the BRDF).

With the balance heuristic each direction ``x`` carries weight ``(n·x)⁺ / Σ_j n_j p_j(x)``; with the
power heuristic (β = 2) ``(n·x)⁺ · n_k p_k(x) / Σ_j (n_j p_j(x))²``. None of this depends on the
BRDF, so a :class:`SampleBlock` is computed once per scene and reused for every material (and the
ground-truth and predicted BRDFs of a comparison see exactly the same directions).

A control variate removes the smooth part: for a constant ``c(λ)`` (:func:`diffuse_floor`, the
BRDF's floor away from the specular peak) ``∫ c L (n·ω)⁺ dω = c · E(n)`` is computed exactly from the
irradiance, and only ``f_r − c`` is sampled. A Lambertian material is then noise-free.

Uniforms come from an Owen-scrambled Sobol set per strategy, Cranley–Patterson-shifted per pixel
from a fixed seed, so renders are deterministic.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.environment import Environment
from specgen_addon.render.geometry import shading_frame


@dataclass(frozen=True)
class EnvSampling:
    """Directions per pixel for each environment strategy (powers of two keep Sobol balanced).

    Defaults (112 directions per pixel) were chosen with ``bench/render_reference.py``; its
    doubling-the-work figures are in docs/dev/renderer.md.
    """

    n_env: int = 32
    n_cosine: int = 16
    lobe_exponents: tuple[float, ...] = (16.0, 128.0, 1024.0, 8192.0)
    n_per_lobe: int = 16
    heuristic: str = "balance"
    control_variate: bool = True
    seed: int = 0
    chunk_pixels: int = 2048

    def __post_init__(self) -> None:
        if self.heuristic not in ("balance", "power"):
            raise SpecGenError(f"unknown MIS heuristic {self.heuristic!r} (balance or power)")
        if min(self.n_env, self.n_cosine, self.n_per_lobe) < 0 or self.total == 0:
            raise SpecGenError("environment sampling needs non-negative counts and at least one sample")

    @property
    def total(self) -> int:
        """Directions per pixel."""
        return self.n_env + self.n_cosine + self.n_per_lobe * len(self.lobe_exponents)

    def scaled(self, factor: float) -> "EnvSampling":
        """Same strategies with every count multiplied by ``factor`` (for convergence checks)."""
        def s(n: int) -> int:
            return max(1, int(round(n * factor))) if n > 0 else 0
        return replace(self, n_env=s(self.n_env), n_cosine=s(self.n_cosine), n_per_lobe=s(self.n_per_lobe))

    def strategies(self) -> list[tuple[str, float, int]]:
        """(kind, lobe exponent, count) of each non-empty strategy."""
        return ([("env", 0.0, self.n_env)] if self.n_env else []) + \
            ([("cos", 0.0, self.n_cosine)] if self.n_cosine else []) + \
            [("lobe", float(e), self.n_per_lobe) for e in self.lobe_exponents if self.n_per_lobe]


@dataclass
class SampleBlock:
    """Environment samples of a block of pixels (rows grouped by pixel).

    ``pixel`` (M,) indexes the block's pixels; ``wi_local`` (M, 3) is the incident direction in the
    pixel's shading frame; ``weight_rgb`` (M, 3) is ``L_env,rgb(ω_i) · MIS weight``, so the estimate
    of pixel p is ``Σ_{pixel=p} f_r(wi, wo_p) · (weight_rgb @ U)``; ``irradiance_rgb`` (P, 3) is E(n).
    """

    pixel: np.ndarray
    wi_local: np.ndarray
    weight_rgb: np.ndarray
    irradiance_rgb: np.ndarray


#: Precomputed point sets (scripts/make_sobol_points.py) for a Python without scipy (a stock
#: Blender): every count and seed the shipped sampling settings (and their halves/doubles) use.
SOBOL_TABLE = Path(__file__).with_name("sobol_points.npz")
SOBOL_TABLE_COUNTS = (4, 8, 16, 32, 64)
SOBOL_TABLE_SEEDS = tuple(range(1, 9))


def sobol_scipy(n: int, seed: int) -> np.ndarray:
    """``n`` Owen-scrambled Sobol points in [0, 1)² from scipy (the single source of the table)."""
    from scipy.stats import qmc

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # non-power-of-two counts lose balance but stay valid
        return qmc.Sobol(d=2, scramble=True, seed=seed).random(n)


@functools.lru_cache(maxsize=1)
def _sobol_table() -> dict[str, np.ndarray]:
    with np.load(SOBOL_TABLE) as z:
        return {k: z[k] for k in z.files}


def _sobol(n: int, seed: int) -> np.ndarray:
    """The points from :data:`SOBOL_TABLE` (scipy's own, stored), or from scipy for a count or seed
    the table lacks. The table comes first: it needs no scipy (a stock Blender), and scipy builds
    its points in compiled code that swallows an exception raised inside it, so a Ctrl-C landing
    there printed a traceback and was lost instead of stopping the run."""
    key = f"n{n}_s{seed}"
    table = _sobol_table()
    if key in table:
        return table[key].copy()
    try:
        return sobol_scipy(n, seed)
    except ImportError:
        raise SpecGenError(f"environment sampling with {n} directions (seed {seed}) needs scipy; "
                           f"without it, counts {SOBOL_TABLE_COUNTS} and seeds {SOBOL_TABLE_SEEDS} work") from None


def _local_to_world(local: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    return local[..., 0:1] * t + local[..., 1:2] * b + local[..., 2:3] * n


def _cosine_dirs(xi: np.ndarray) -> np.ndarray:
    r = np.sqrt(xi[..., 0])
    phi = 2.0 * np.pi * xi[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - xi[..., 0], 0.0))], -1)


def _lobe_dirs(xi: np.ndarray, exponent: float) -> np.ndarray:
    cos_a = np.power(np.maximum(xi[..., 0], 1e-300), 1.0 / (exponent + 1.0))
    sin_a = np.sqrt(np.maximum(1.0 - cos_a * cos_a, 0.0))
    phi = 2.0 * np.pi * xi[..., 1]
    return np.stack([sin_a * np.cos(phi), sin_a * np.sin(phi), cos_a], -1)


class EnvSampler:
    """Builds :class:`SampleBlock` s for an environment and sampling settings."""

    def __init__(self, environment: Environment, sampling: EnvSampling, n_pixels: int):
        self.env = environment
        self.sampling = sampling
        self.strategies = sampling.strategies()
        self.points = [_sobol(n, sampling.seed + 1 + k) for k, (_, _, n) in enumerate(self.strategies)]
        self.shifts = np.random.default_rng(sampling.seed).random((len(self.strategies), n_pixels, 2))

    def block(self, n: np.ndarray, t: np.ndarray, b: np.ndarray, wo: np.ndarray,
              pixel_ids: np.ndarray) -> SampleBlock:
        """Samples for pixels with world normals ``n`` (P, 3), frame (t, b), camera direction ``wo``."""
        p = n.shape[0]
        wo_w = np.broadcast_to(wo, n.shape)
        refl = 2.0 * np.einsum("pk,pk->p", n, wo_w)[:, None] * n - wo_w
        rt, rb = shading_frame(refl)
        dirs = []
        for k, (kind, exponent, _) in enumerate(self.strategies):
            xi = np.mod(self.points[k][None, :, :] + self.shifts[k][pixel_ids][:, None, :], 1.0)
            if kind == "env":
                dirs.append(self.env.sample(xi))
            elif kind == "cos":
                dirs.append(_local_to_world(_cosine_dirs(xi), t[:, None], b[:, None], n[:, None]))
            else:
                dirs.append(_local_to_world(_lobe_dirs(xi, exponent), rt[:, None], rb[:, None],
                                            refl[:, None]))
        d = np.concatenate(dirs, axis=1)                       # (P, S, 3) world directions
        d /= np.sqrt(np.einsum("psk,psk->ps", d, d))[..., None]
        local = np.einsum("psk,pjk->psj", d, np.stack([t, b, n], axis=1))  # shading frame
        cos_i = local[..., 2]
        cos_r = np.maximum(np.einsum("psk,pk->ps", d, refl), 1e-300)
        log_cos_r = np.log(cos_r)
        terms = []                                             # a_j = n_j p_j(x)
        for kind, exponent, count in self.strategies:
            if kind == "env":
                terms.append(count * self.env.pdf(d))
            elif kind == "cos":
                terms.append(count * np.maximum(cos_i, 0.0) / np.pi)
            else:
                terms.append(count * (exponent + 1.0) / (2.0 * np.pi) * np.exp(exponent * log_cos_r))
        if self.sampling.heuristic == "balance":
            inv_q = 1.0 / np.maximum(np.sum(terms, axis=0), 1e-300)
        else:
            own = np.concatenate([terms[k][:, off:off + cnt] for k, (off, cnt) in
                                  enumerate(self._offsets())], axis=1)
            inv_q = own / np.maximum(np.sum(np.square(terms), axis=0), 1e-300)
        valid = (cos_i > 0) & (inv_q > 0)
        pix = np.broadcast_to(np.arange(p)[:, None], cos_i.shape)[valid]
        wi_l = local[valid]
        weight = self.env.radiance_rgb(d[valid]) * (cos_i[valid] * inv_q[valid])[:, None]
        irradiance = self.env.irradiance_rgb(n) if self.sampling.control_variate else np.zeros((p, 3))
        return SampleBlock(pix.astype(np.int32), wi_l, weight, irradiance)

    def _offsets(self) -> list[tuple[int, int]]:
        offs, start = [], 0
        for _, _, count in self.strategies:
            offs.append((start, count))
            start += count
        return offs


#: Probe directions of :func:`diffuse_floor`: polar angles and azimuths (radians).
_PROBE_THETA = np.radians([0.0, 20.0, 40.0, 60.0])
_PROBE_PHI = np.radians([0.0, 90.0, 180.0])
_PROBE_MIN_THETA_H = np.radians(15.0)


def _probe_pairs() -> tuple[np.ndarray, np.ndarray]:
    ti, to, ph = np.meshgrid(_PROBE_THETA, _PROBE_THETA, _PROBE_PHI, indexing="ij")
    ti, to, ph = ti.ravel(), to.ravel(), ph.ravel()
    wi = np.stack([np.sin(ti) * np.cos(ph), np.sin(ti) * np.sin(ph), np.cos(ti)], -1)
    wo = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], -1)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    keep = np.arccos(np.clip(h[:, 2], -1, 1)) >= _PROBE_MIN_THETA_H
    return wi[keep], wo[keep]


def diffuse_floor(eval_fn: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Control-variate constant ``c`` (C,): the BRDF's minimum over probe pairs away from the
    specular peak (half-vector angle ≥ 15°, polar angles ≤ 60°), clipped at 0.

    Any ``c`` keeps the environment estimate unbiased; this one removes a Lambertian part entirely.
    """
    wi, wo = _probe_pairs()
    values = np.asarray(eval_fn(wi, wo), dtype=np.float64)
    return np.clip(np.nan_to_num(values.min(axis=0), nan=0.0), 0.0, None)
