"""Real RGB measurements in joint training (paper §3.3): measured RGL RGB files supervise the RGB side.

The corpus supervises both branches; the real files, too few to fill a batch by chance, are drawn
deliberately: ``real_materials_per_step`` of them at every step (a fixed share of the batch,
whatever the corpus' size), each augmented into a new, physically consistent material:

* **exposure** and **white balance**: gains ``g = 2^(σ_e·z) · exp(σ_wb·z_c)`` (per channel, the
  white-balance part of geometric mean 1) multiply the measured RGB BRDF *and* its canonical input
  photo, which is exact because a render is linear in the BRDF;
* **PNG**: with probability ½ the photo is handed over as its 8-bit sRGB version (highlights
  clipped), as the corpus' inputs are;
* **rotations of the lighting** are implicit: an isotropic BRDF is a function of (θh, θd, φd), and
  the targets are drawn uniformly in that space.

Each real material adds ``w_real · (L_colour + L_grey)`` to the loss, with its planes' total
variation in the TV term:

* ``L_grey``: the paper's RGB-branch term, the μ-law MSE of the grey response (λ-averaged features)
  against μ(mean_c f_c);
* ``L_colour``: the spectral prediction at :data:`REAL_BANDS_NM` projected to linear sRGB under D65
  (as the evaluation projects a table to score it against a real file), μ-law MSE per channel
  against the measured f_c: the colour the grey term cannot teach.

Targets come from the file tabulated once on the MERL grid (cached), so the network is taught what
a table can hold; ``real_exclude`` leaves files out (a cross-validation fold's held-out files).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.spectra import reflectance_to_linear_srgb, wavelength_grid
from specgen_addon.train.data import TrainingMaterial, load_file_materials, sample_angles
from specgen_addon.brdf.formats import load_brdf
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import mu_law_encode
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.train.losses import inverse_mu_law, masked_mse
from specgen_addon.train.network_input import network_inputs, png_like

#: Bands (nm) at which the spectral branch is queried and projected to RGB for a real material.
REAL_BANDS_NM = wavelength_grid(380.0, 780.0, 16)
#: Where the real RGB files live when the config names no folder (../shared/data/rgl).
DEFAULT_REAL_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgl"


def real_files(folder: str | Path, exclude: Sequence[str] = ()) -> list[Path]:
    """The RGB ``*.bsdf`` files of ``folder`` (sorted), less those whose stem is in ``exclude``.

    SpecGenError when the folder is missing or ``exclude`` names a file it does not hold (a typo
    would otherwise leak a held-out file into training).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise SpecGenError(f"{folder}: real RGB folder not found")
    files = sorted(folder.glob("*.bsdf"))
    unknown = sorted(set(exclude) - {p.stem for p in files})
    if unknown:
        raise SpecGenError(f"real_exclude names files not in {folder}: {', '.join(unknown)}")
    return [p for p in files if p.stem not in set(exclude)]


def srgb_projection(bands_nm: np.ndarray = REAL_BANDS_NM) -> np.ndarray:
    """``(K, 3)`` matrix taking a BRDF sampled at ``bands_nm`` to linear sRGB under D65."""
    return np.asarray(reflectance_to_linear_srgb(np.eye(len(bands_nm)), np.asarray(bands_nm, float), "D65"),
                      dtype=np.float32)


def augment_gains(rng: np.random.Generator, exposure_stops: float, white_balance: float) -> np.ndarray:
    """Per-channel gains ``(3,)``: an exposure of ``2^(exposure_stops·z)`` times white-balance gains
    ``exp(white_balance·z_c)`` normalised to geometric mean 1 (no draws when both are 0)."""
    gain = np.ones(3)
    if exposure_stops > 0:
        gain = gain * 2.0 ** (exposure_stops * rng.standard_normal())
    if white_balance > 0:
        wb = white_balance * rng.standard_normal(3)
        gain = gain * np.exp(wb - wb.mean())
    return gain


@dataclass
class RealBatch:
    """Real materials of one step: inputs ``(B, 3, S, S)``, angles (radians) ``(B, N)``, μ-law RGB
    targets ``(B, N, 3)``, μ-law grey targets ``(B, N)`` and the above-horizon mask ``(B, N)``."""

    images: np.ndarray
    theta_h: np.ndarray
    theta_d: np.ndarray
    phi_d: np.ndarray
    target_rgb: np.ndarray
    target_grey: np.ndarray
    valid: np.ndarray
    names: list[str]


@dataclass
class RealSource:
    """The real RGB materials a run trains on (tabulated) and their canonical input photos."""

    materials: list[TrainingMaterial]
    photos: list[np.ndarray]
    per_step: int
    exposure_stops: float = 0.0
    white_balance: float = 0.0
    png_p: float = 0.5

    def __len__(self) -> int:
        return len(self.materials)

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.materials]

    def batch(self, seed: int, step: int, image_size: int, n_angles: int, mu: float) -> RealBatch:
        """The real batch of ``step``: a pure function of ``(seed, step)`` (its own stream, so the
        corpus draws of a run stay as they were without real files)."""
        rng = np.random.default_rng([seed, step, 0x2EA1])
        idx = np.sort(rng.choice(len(self), size=min(self.per_step, len(self)), replace=False))
        imgs, ths, tds, pds, rgbs, greys, vals = [], [], [], [], [], [], []
        for i in idx:
            gain = augment_gains(rng, self.exposure_stops, self.white_balance)
            photo = self.photos[i] * gain.astype(np.float32)
            if rng.random() < self.png_p:
                photo = png_like(photo)
            imgs.append(network_inputs([photo], image_size)[0])
            th, td, pd = sample_angles(rng, n_angles)
            wi, wo = io_from_half_diff(th, td, pd)
            f = np.asarray(self.materials[i].brdf.eval_rgb(wi, wo), dtype=np.float64) * gain
            f = np.where(np.isfinite(f), np.maximum(f, 0.0), 0.0)
            ths.append(th), tds.append(td), pds.append(pd)
            rgbs.append(mu_law_encode(f, mu))
            greys.append(mu_law_encode(f.mean(axis=1), mu))
            vals.append((wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6))
        f32 = lambda xs: np.stack(xs).astype(np.float32)
        return RealBatch(f32(imgs), f32(ths), f32(tds), f32(pds), f32(rgbs), f32(greys), np.stack(vals),
                         [self.materials[i].name for i in idx])


def real_loss(model: Any, b: RealBatch, projection: torch.Tensor | None = None,
              bands_nm: np.ndarray = REAL_BANDS_NM) -> tuple[torch.Tensor, torch.Tensor]:
    """``(L_colour + L_grey, TV of the planes)`` of a real batch (module docstring)."""
    dev = next(model.parameters()).device
    t = lambda a: torch.from_numpy(np.ascontiguousarray(a)).to(dev)
    th, td, pd, valid = t(b.theta_h), t(b.theta_d), t(b.phi_d), t(b.valid.astype(np.float32))
    planes = model.planes(t(b.images))
    B, N = th.shape
    K = len(bands_nm)
    lam = torch.as_tensor(np.asarray(bands_nm, np.float32), device=dev).repeat(B, N)       # (B, N·K)
    rep = lambda x: x.repeat_interleave(K, dim=1)
    r = model.query(planes, rep(th), rep(td), rep(pd), lam).reshape(B, N, K)
    mu = float(model.cfg.mu)
    m = projection if projection is not None else torch.from_numpy(srgb_projection(bands_nm))
    rgb = (inverse_mu_law(r.clamp(max=3.0), mu) @ m.to(dev)).clamp_min(0.0)               # (B, N, 3)
    pred_rgb = torch.log1p(mu * rgb) / math.log1p(mu)
    v3 = valid.unsqueeze(-1).expand(-1, -1, 3)
    colour = masked_mse(pred_rgb, t(b.target_rgb), v3)
    grey = masked_mse(model.query(planes, th, td, pd, None), t(b.target_grey), valid)
    return colour + grey, model.tv_loss(planes)


def real_source(tcfg: Any, cache_dir: str | Path, log: Callable[[str], None] = print) -> RealSource | None:
    """The :class:`RealSource` a training config asks for (None when ``real_materials_per_step`` is 0):
    the files of ``real_rgb_dir`` (default ../shared/data/rgl) less ``real_exclude``, tabulated and
    their canonical inputs rendered once into ``cache_dir``."""
    if not tcfg.real_materials_per_step:
        return None
    files = real_files(tcfg.real_rgb_dir or DEFAULT_REAL_DIR, tcfg.real_exclude)
    if not files:
        raise SpecGenError("real_materials_per_step > 0 but every real RGB file is excluded")
    cache_dir = Path(cache_dir)
    mats = load_file_materials(files, cache_dir, progress=log)
    if any(m.spectral for m in mats):
        raise SpecGenError("the real RGB folder holds a spectral file; real_rgb_dir takes RGB measurements")
    photos = [canonical_photo(p, cache_dir, log) for p in files]
    return RealSource(mats, photos, tcfg.real_materials_per_step, tcfg.real_exposure_jitter,
                      tcfg.real_white_balance_jitter)


def canonical_photo(path: Path, cache_dir: Path, log: Callable[[str], None] = print) -> np.ndarray:
    """The canonical input photo ``(128, 128, 3)`` of a measured file, as the evaluation renders it
    (:func:`specgen_addon.photo.sphere_image.render_input` of the file itself), cached by content."""
    key = hashlib.sha1(f"{path.resolve()}:{path.stat().st_size}:{path.stat().st_mtime_ns}".encode()).hexdigest()[:16]
    cached = Path(cache_dir) / f"real_input_{path.stem}_{key}.npy"
    if cached.is_file():
        return np.load(cached)
    log(f"rendering the canonical input of {path.name}")
    photo = np.asarray(input_image.render_input(load_brdf(path)), dtype=np.float32)
    cached.parent.mkdir(parents=True, exist_ok=True)
    tmp = cached.with_name(cached.stem + ".tmp.npy")
    np.save(tmp, photo)
    tmp.replace(cached)
    return photo
