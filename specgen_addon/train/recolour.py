"""Training materials recoloured on the fly: new combinations of familiar spectra, with exact inputs.

The network fits its training materials 1.1 dB better than held-out ones, and a training material
whose reflectances are swapped for *other training* spectra loses as much as with held-out ones
(lab/notebook): it learns the corpus's materials as combinations.
This module makes new combinations at every step without rendering anything new.

A corpus BRDF is affine in many of its reflectance spectra ρ(λ) (a diffuse base under a coat, a
sheen's base, a lobe's diffuse term): per band, ``f(ρ) = f(0) + ρ(λ) · (f(1) − f(0))``. A render is
linear in the BRDF, band by band, so the canonical input's spectral radiance is
``L(ρ) = L₀ + ρ(λ) · L₁`` with ``L₀`` the render with ρ ≡ 0 and ``L₁`` that with ρ ≡ 1 minus
``L₀``. With those two per-band renders cached, the canonical input of the material under *any*
ρ is a weighted sum, exact up to the renderer's own sampling (the same sample pattern serves
both), and its targets are the analytic BRDF with ρ replaced.

Which reflectance a material is affine in is checked numerically (:func:`affine_slot`), not
listed per family: a spectrum that enters through a logarithm (a tinted coat's absorption) or a
clamp fails the check and is never swapped. Units: wavelengths in nm, radiance as the input
renderer's (linear sRGB after :func:`specgen_addon.spectral.spectra.spectral_to_linear_srgb`).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.corpus.material import Reflectance
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM
from specgen_addon.train.data import TrainingMaterial, material_key
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.train.data import render_all
from specgen_addon.train.lighting_mix import quantise, resample_stack

#: Bands (nm) the canonical input is rendered in (the input renderer's grid).
BANDS_NM = spectra.DEFAULT_WAVELENGTHS_NM
#: Relative tolerance of the affinity check (float64 evaluations of the same points).
AFFINE_RTOL = 1e-7
_ZERO = Reflectance("recolour/zero", (0.0,) * REFLECTANCE_GRID_NM.size)
_ONE = Reflectance("recolour/one", (1.0,) * REFLECTANCE_GRID_NM.size)


def reflectance_paths(obj: Any, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Field paths of every (not None) :class:`Reflectance` in a frozen-dataclass material, in field order."""
    if isinstance(obj, Reflectance):
        return [prefix]
    if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
        return []
    out: list[tuple[str, ...]] = []
    for field in dataclasses.fields(obj):
        if field.init:
            out += reflectance_paths(getattr(obj, field.name), prefix + (field.name,))
    return out


def with_reflectance(obj: Any, path: tuple[str, ...], value: Reflectance) -> Any:
    """``obj`` with the reflectance at ``path`` replaced by ``value`` (everything else kept)."""
    if not path:
        return value
    head = path[0]
    return dataclasses.replace(obj, **{head: with_reflectance(getattr(obj, head), path[1:], value)})


def reflectance_at(obj: Any, path: tuple[str, ...]) -> Reflectance:
    for name in path:
        obj = getattr(obj, name)
    return obj


def _probe_points(n: int = 256) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(12345)

    u = rng.random((3, n))
    return io_from_half_diff(u[0] ** 2 * (np.pi / 2), u[1] * (np.pi / 2), u[2] * np.pi)


def is_affine_in(brdf: Any, path: tuple[str, ...], wavelengths_nm: np.ndarray = BANDS_NM) -> bool:
    """Whether ``f(ρ) = f(0) + ρ(λ)(f(1) − f(0))`` holds for the reflectance at ``path`` (two test spectra)."""
    wi, wo = _probe_points()
    w = np.asarray(wavelengths_nm, np.float64)
    f0 = np.asarray(with_reflectance(brdf, path, _ZERO).eval(wi, wo, w), np.float64)
    f1 = np.asarray(with_reflectance(brdf, path, _ONE).eval(wi, wo, w), np.float64)
    if not (np.all(np.isfinite(f0)) and np.all(np.isfinite(f1))) or np.max(np.abs(f1 - f0)) <= 0.0:
        return False
    rng = np.random.default_rng(7)
    for _ in range(2):
        rho = Reflectance("recolour/probe", tuple(float(x) for x in rng.random(REFLECTANCE_GRID_NM.size)))
        f = np.asarray(with_reflectance(brdf, path, rho).eval(wi, wo, w), np.float64)
        pred = f0 + rho.at(w)[None, :] * (f1 - f0)
        if not np.allclose(f, pred, rtol=AFFINE_RTOL, atol=AFFINE_RTOL * np.max(np.abs(f))):
            return False
    return True


def affine_slot(brdf: Any) -> tuple[str, ...] | None:
    """The first reflectance (field order) the BRDF is affine in, or None (nothing to swap)."""
    for path in reflectance_paths(brdf):
        if is_affine_in(brdf, path):
            return path
    return None


def spectrum_pool(materials: Sequence[TrainingMaterial]) -> np.ndarray:
    """Distinct reflectances (K, len(REFLECTANCE_GRID_NM)) of these (training) materials, in first-seen order.

    Drawing replacements only from the training materials' own spectra keeps every held-out
    spectrum held out.
    """
    seen: dict[tuple[float, ...], None] = {}
    for m in materials:
        for path in reflectance_paths(m.brdf):
            seen.setdefault(tuple(reflectance_at(m.brdf, path).values), None)
    if not seen:
        return np.zeros((0, REFLECTANCE_GRID_NM.size))
    return np.array(list(seen), dtype=np.float64)


def recoloured(mat: TrainingMaterial, path: tuple[str, ...], values: np.ndarray) -> TrainingMaterial:
    """``mat`` with the reflectance at ``path`` replaced by ``values`` (on the corpus grid)."""
    rho = Reflectance("recolour", tuple(float(x) for x in values))
    return dataclasses.replace(mat, brdf=with_reflectance(mat.brdf, path, rho))


def render_affine_pair(brdf: Any, path: tuple[str, ...]) -> np.ndarray:
    """``(2, Λ, 128, 128)`` float32: the canonical input's spectral radiance (× the input exposure)
    with ρ ≡ 0, and with ρ ≡ 1 minus that (:data:`BANDS_NM`; the canonical scene and its samples)."""
    scene = input_image._scene(input_image.CANONICAL_ENV, 0.0, input_image.CANONICAL_SIZE)
    l0, l1 = (np.asarray(scene.render_spectral(with_reflectance(brdf, path, value), BANDS_NM).spectral,
                         np.float64) * input_image.EXPOSURE for value in (_ZERO, _ONE))
    return np.stack([l0, l1 - l0]).transpose(0, 3, 1, 2).astype(np.float32)


def combine(pair: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear-sRGB canonical input ``(H, W, 3)`` of the material with reflectance ``values`` (on the
    corpus grid), from its ``pair``: as :func:`specgen_addon.photo.sphere_image.render_input` would render it."""
    rho = np.interp(BANDS_NM, REFLECTANCE_GRID_NM, np.asarray(values, np.float64)).astype(np.float32)
    radiance = pair[0].astype(np.float32) + rho[:, None, None] * pair[1].astype(np.float32)
    rgb = spectra.spectral_to_linear_srgb(radiance.transpose(1, 2, 0), BANDS_NM)
    return np.clip(rgb, 0.0, None).astype(np.float32)


def recoloured_input(pair: np.ndarray, values: np.ndarray, png: bool, size: int) -> np.ndarray:
    """The network's input ``(3, size, size)``: :func:`combine`, 8-bit PNG-quantised at full size when
    ``png`` (as the cached ``canonical_png`` component is), then resampled as the component cache is."""
    image = combine(pair, values)
    if png:
        image = quantise(image)
    return resample_stack(image[None], size)[0].astype(np.float32)


@dataclasses.dataclass
class RecolourSource:
    """What a step needs to recolour a material set's members: per material its affine slot and
    pair (None: not recolourable), the pool of replacement spectra, and the chance per draw."""

    slots: list[tuple[str, ...] | None]
    pairs: list[np.ndarray | None]
    pool: np.ndarray
    p: float

    def draw(self, rng: np.random.Generator, mat: TrainingMaterial, i: int, size: int
             ) -> tuple[TrainingMaterial, np.ndarray] | None:
        """With chance ``p`` (when material ``i`` has a pair): the material recoloured with a random
        pool spectrum and its canonical input (linear or PNG, evenly); else None. Draws from ``rng``
        only for recolourable materials."""
        if self.pairs[i] is None or len(self.pool) == 0 or rng.random() >= self.p:
            return None
        values = self.pool[rng.integers(len(self.pool))]
        png = bool(rng.random() < 0.5)
        return recoloured(mat, self.slots[i], values), recoloured_input(self.pairs[i], values, png, size)


@dataclasses.dataclass
class AffinePairCache:
    """Per material, its affine slot's field path and two canonical renders (:func:`render_affine_pair`,
    float16) in one ``.npz`` (an empty pair when it has no affine reflectance), keyed by content."""

    cache_dir: Path

    def path(self, mat: TrainingMaterial) -> Path:
        return self.cache_dir / f"affine_{mat.name.replace('/', '_')}_{material_key(mat)}.npz"

    def missing(self, mats: Sequence[TrainingMaterial]) -> list[TrainingMaterial]:
        return [m for m in mats if not self.path(m).is_file()]

    def make(self, mat: TrainingMaterial) -> None:
        slot = affine_slot(mat.brdf)
        arr = np.zeros((0,), np.float16) if slot is None else render_affine_pair(mat.brdf, slot).astype(np.float16)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        path = self.path(mat)
        tmp = path.with_name(path.stem + f".{os.getpid()}.tmp.npz")
        np.savez(tmp, pair=arr, slot=np.array(slot or (), dtype=str))
        tmp.replace(path)

    def fill(self, mats: Sequence[TrainingMaterial], workers: int = 2, progress=None) -> None:
        """Render what is missing on ``workers`` processes."""
        todo = self.missing(mats)
        if todo:
            render_all(self.make, todo, workers, progress)

    def source(self, mats: Sequence[TrainingMaterial], p: float) -> RecolourSource:
        """The loaded pairs of ``mats`` (all rendered) with the pool of their own spectra."""
        pairs: list[np.ndarray | None] = []
        slots: list[tuple[str, ...] | None] = []
        for m in mats:
            with np.load(self.path(m)) as z:
                arr, slot = z["pair"], tuple(str(x) for x in z["slot"])
            pairs.append(arr if arr.size else None)
            slots.append(slot if arr.size else None)
        return RecolourSource(slots, pairs, spectrum_pool(mats), float(p))
