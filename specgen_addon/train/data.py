"""Training samples for SpecGen (paper §3.3, §4.2): target points and input images per material.

A *training material* is any BRDF object of the project's protocol (``eval(wi, wo, λ)`` and/or
``eval_rgb(wi, wo)``) plus its pre-rendered input images (several lightings: augmentation).
Targets are drawn on the fly, deterministically from a seeded generator:

* angles uniform in the MERL index space (``√θh``, ``θd``, ``φd`` uniform), i.e. the table's own
  sampling density, with configurations below the horizon masked out of the loss;
* spectral materials: evaluated on a fixed band grid (nm), each angle keeping a few random bands;
  target ``r' = μ(f_r)``;
* RGB materials: target ``g' = μ(mean_c f_r,c)`` (μ-law of the channel mean, §3.3).
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import mu_law_encode
from specgen_addon.brdf.formats import detect_format, load_brdf
from specgen_addon.brdf.formats.rgl import tabulate_rgl
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.common.processes import context, pool_workers, quiet_worker

BRDF_SUFFIXES = (".binary", ".bsdf")


@dataclass
class TrainingMaterial:
    """One material: a BRDF, whether it is supervised spectrally or in RGB, and a stable name."""

    name: str
    brdf: Any
    spectral: bool
    split: str = "train"


@dataclass
class Batch:
    """Points of several materials: angles (radians), wavelengths (nm, spectral only), targets r'.

    Arrays are ``(B, N)``; ``valid`` masks points below the horizon; ``images`` ``(B, 3, S, S)``.
    """

    images: np.ndarray
    theta_h: np.ndarray
    theta_d: np.ndarray
    phi_d: np.ndarray
    wavelength_nm: np.ndarray | None
    target: np.ndarray
    valid: np.ndarray


def sample_angles(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` Rusinkiewicz angles (radians) uniform in MERL index space (√-warped θh)."""
    u = rng.random((3, n))
    return u[0] ** 2 * (math.pi / 2), u[1] * (math.pi / 2), u[2] * math.pi


def material_targets(mat: TrainingMaterial, theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray,
                     wavelengths_nm: np.ndarray | None, mu: float = 255.0) -> tuple[np.ndarray, np.ndarray]:
    """μ-law targets ``(n, L)`` at angles × wavelengths (nm), and the above-horizon mask ``(n,)``.

    For an RGB material (``wavelengths_nm=None``) the single column is the μ-law of the channel
    mean of the RGB BRDF (§3.3).
    """
    wi, wo = io_from_half_diff(theta_h, theta_d, phi_d)
    valid = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
    if wavelengths_nm is None:
        fr = np.asarray(mat.brdf.eval_rgb(wi, wo), dtype=np.float64).mean(axis=1, keepdims=True)
    else:
        fr = np.asarray(mat.brdf.eval(wi, wo, wavelengths_nm), dtype=np.float64)
    fr = np.where(np.isfinite(fr), np.maximum(fr, 0.0), 0.0)
    return mu_law_encode(fr, mu), valid


def make_batch(materials: Sequence[TrainingMaterial], images: Sequence[np.ndarray], rng: np.random.Generator,
               n_angles: int, n_wavelengths: int, spectral: bool,
               wavelength_grid_nm: np.ndarray, mu: float = 255.0,
               evaluate: Sequence[int] | None = None) -> Batch:
    """Sample ``n_angles`` angles per material; spectral materials are evaluated on
    ``wavelength_grid_nm`` and each angle keeps ``n_wavelengths`` of those bands at random.

    ``evaluate``: indices of the materials whose BRDF targets are computed (a data-parallel rank's
    share); the others get zero targets. The random draws are the same either way.
    """
    ths, tds, pds, lams, tgts, vals = [], [], [], [], [], []
    grid = np.asarray(wavelength_grid_nm, dtype=np.float64)
    wanted = None if evaluate is None else set(int(i) for i in evaluate)
    for i, mat in enumerate(materials):
        th, td, pd = sample_angles(rng, n_angles)
        if wanted is None or i in wanted:
            tgt, valid = material_targets(mat, th, td, pd, grid if spectral else None, mu)
        else:
            wi, wo = io_from_half_diff(th, td, pd)
            valid = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
            tgt = np.zeros((n_angles, grid.size if spectral else 1))
        n_l = n_wavelengths if spectral else 1
        if spectral:
            cols = rng.integers(0, grid.size, size=(n_angles, n_l))
            tgt = np.take_along_axis(tgt, cols, axis=1)
            lams.append(grid[cols].ravel())
        ths.append(np.repeat(th, n_l))
        tds.append(np.repeat(td, n_l))
        pds.append(np.repeat(pd, n_l))
        tgts.append(tgt.ravel())
        vals.append(np.repeat(valid, n_l))
    f32 = lambda xs: np.stack(xs).astype(np.float32)  # noqa: E731
    return Batch(images=np.stack(images).astype(np.float32), theta_h=f32(ths), theta_d=f32(tds),
                 phi_d=f32(pds), wavelength_nm=f32(lams) if spectral else None, target=f32(tgts),
                 valid=np.stack(vals))


def render_all(make: Callable[[Any], None], todo: Sequence[Any], workers: int = 2,
               progress: Callable[[float], None] | None = None, chunksize: int = 4) -> None:
    """``make(item)`` for every item, on ``workers`` processes (in order when 1), reporting the
    fraction done: the render caches' fill. Inside a pool worker (an ablation arm), or where
    ``make`` cannot be pickled to a worker, the items are made in this process."""
    workers = pool_workers(workers, make, per_task=True)
    if workers <= 1:
        for i, item in enumerate(todo):
            make(item)
            if progress:
                progress((i + 1) / len(todo))
        return
    with context().Pool(workers, initializer=quiet_worker) as pool:
        for i, _ in enumerate(pool.imap_unordered(make, todo, chunksize=chunksize)):
            if progress:
                progress((i + 1) / len(todo))


def find_brdf_files(dirs: Sequence[str | Path]) -> list[Path]:
    """MERL ``.binary`` and RGL ``.bsdf`` files in the given directories (sorted, non-recursive)."""
    files: list[Path] = []
    for d in dirs:
        d = Path(d)
        if not d.is_dir():
            raise SpecGenError(f"{d}: BRDF directory not found")
        files += sorted(p for p in d.iterdir() if p.suffix.lower() in BRDF_SUFFIXES)
    return files


def load_file_materials(files: Sequence[Path], cache_dir: Path,
                        progress: Callable[[str], None] | None = None) -> list[TrainingMaterial]:
    """Load measured BRDF files as materials; RGL files are tabulated once (cached) for speed.

    RGB files supervise the RGB branch; spectral RGL files the spectral branch.
    """
    out = []
    for path in files:
        brdf = load_brdf(path)
        if detect_format(path) == "rgl":
            key = hashlib.sha1(f"{path.resolve()}:{path.stat().st_size}:{path.stat().st_mtime_ns}"
                               .encode()).hexdigest()[:16]
            cached = cache_dir / f"table_{path.stem}_{key}.npz"
            if cached.is_file():
                brdf = BRDFTable.load(cached)
            else:
                if progress:
                    progress(f"tabulating {path.name}")
                # in the order io_from_half_diff gives (the model card's table ceilings)
                table = tabulate_rgl(brdf, order="fixed")
                cache_dir.mkdir(parents=True, exist_ok=True)
                table.save(cached, overwrite=True)
                brdf = table
        out.append(TrainingMaterial(name=path.stem, brdf=brdf, spectral=bool(brdf.is_spectral)))
    return out


def material_key(mat: TrainingMaterial) -> str:
    """Stable content key of a material for the render cache (parameters or source file)."""
    brdf = mat.brdf
    if hasattr(brdf, "to_dict"):
        ident = repr(sorted(brdf.to_dict().items()))
    else:
        ident = repr(getattr(brdf, "metadata", {}).get("source", mat.name))
    return hashlib.sha1(f"{mat.name}|{ident}".encode()).hexdigest()[:16]


@dataclass
class InputImageCache:
    """Input renders ``(H, W, 3)`` per (material, lighting variant), cached as ``.npy`` files.

    ``render(brdf, variant)`` makes one image; renders are model-independent (the network's
    resampling happens on load), so every training run and ablation arm shares them.
    """

    cache_dir: Path
    render: Callable[[Any, int], np.ndarray]
    tag: str = ""

    def path(self, mat: TrainingMaterial, variant: int) -> Path:
        return self.cache_dir / f"input_{mat.name.replace('/', '_')}_{material_key(mat)}{self.tag}_v{variant}.npy"

    def missing(self, mats: Sequence[TrainingMaterial], n_variants: int) -> list[tuple[TrainingMaterial, int]]:
        return [(m, v) for v in range(n_variants) for m in mats if not self.path(m, v).is_file()]

    def make(self, mat: TrainingMaterial, variant: int) -> None:
        arr = np.asarray(self.render(mat.brdf, variant), dtype=np.float32)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        path = self.path(mat, variant)
        tmp = path.with_name(path.stem + f".{os.getpid()}.tmp.npy")
        np.save(tmp, arr)
        tmp.replace(path)

    def fill(self, mats: Sequence[TrainingMaterial], n_variants: int, workers: int = 2,
             progress: Callable[[float], None] | None = None) -> None:
        """Render what is missing, variant-major (lighting scenes are reused), on ``workers`` processes."""
        todo = self.missing(mats, n_variants)
        if todo:
            render_all(self._make_task, todo, workers, progress, chunksize=1)

    def _make_task(self, task: tuple[TrainingMaterial, int]) -> None:
        self.make(*task)

    def load(self, mat: TrainingMaterial, n_variants: int) -> list[np.ndarray]:
        return [np.load(self.path(mat, v)) for v in range(n_variants)]
