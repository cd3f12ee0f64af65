"""The network's own latent fitted to the photo: its prior, the photo's measurement (torch only).

The encoder maps the photo to a latent ``z`` (and its mean colour ``c``, which feeds the spectral
code); the decoder turns ``(z, c)`` into the six planes and so into the whole table. The
encoder's guess is not the best the decoder can do: latents fitted to the *true* BRDF score
7–12 dB higher (lab/notebook). This module fits ``(z, c)`` to the
only measurement there is, the photo, by rendering the decoded table under the photo's lighting
and descending on the photo's error. The result stays on the decoder's manifold, so the angles
the photo does not show follow the network's prior, not a basis of hats.

The render is the refinement's operator (:class:`specgen_addon.generate.refine.operator.PhotoOperator`):
the photo as a sum over each pixel's light and environment samples of the table's trilinear
lookups. Rendering every sample every step would cost about a minute per step on two cores, so
each step renders

* a batch of the sphere's pixels (``batch_pixels``, drawn per step),
* a fixed draw of ``env_samples`` environment samples per pixel (weighted by how many it
  stands for) and every light sample,
* at the grid node nearest each lookup, at ``fit_wavelengths_nm`` interpolated linearly onto the
  operator's integration grid,

and adds the *defect* of that cheap render against the exact one (the full table, every sample,
trilinear, every band): ``photo(z) ≈ cheap(z) + [exact(z_r) − cheap(z_r)]``, recomputed at the
current latent ``z_r`` every ``refresh_every`` steps. The cheap render's sampling noise and
rounding cancel to first order, and what is fitted is the exact render's error.

Each exact render is also the fit's check, since the photo is the measurement: the latent whose
exact photo reproduces the photo best (RGB PSNR over the sphere, as the refinement reports it) is
kept, and when a refresh finds the photo reproduced worse than at the best latent so far, the fit
returns there with half the step size. The encoder's latent is the first candidate, so the fit
never returns a table that reproduces the photo worse than the network's. With ``holdout`` the fit
sees only one half of a checkerboard of 8-pixel blocks (:mod:`specgen_addon.generate.refine.holdout`) and
the other half does the judging, so a latent that fits the photo's noise is not kept for a gain
the held-out pixels do not share.

A resampled sphere (every camera photo) is blurred by the crop; as in the refinement
(:mod:`specgen_addon.generate.refine.blur`) the exact render is blurred by a Gaussian whose σ is the
candidate that makes the network's own render reproduce the photo best (σ = 0 for a sphere copied
pixel for pixel), and pixels whose blurred neighbourhood leaves the sphere are not fitted.

With ``keep_peak`` the specular peak finer than the photo's pixel is left to the network: the θh
nodes below :func:`unresolved_theta_h_nodes` (the angle the normal turns across one pixel at the
sphere's centre) keep the encoder's values in every render and in the returned table, so the fit
moves only what the photo resolves. Without it the fit can reshape a sub-pixel peak to suit a
pixel's integral (lab/notebook); with it, a coat whose peak the
network has wrong cannot be corrected, and on fresh validation photos it lost 0.6 dB against the
fit without it, so it is off (lab/notebook).

The loss is the squared difference of ``log(ε + rgb)``, ε a fraction of the photo's level
(:func:`specgen_addon.render.photo_reproduction.photo_scale`), so the body and the highlight both count;
pixels clipped in an 8/16-bit photo are left out. ``z`` is kept ≥ 0 (the encoder's last ReLU).

Needs torch (the gradient through the decoder): it runs from the CLI (``infer --latent-fit``) and
:func:`specgen_addon.generate.pipeline.generate`, not in a stock Blender (the panel's onnxruntime has no
gradients).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.spectral.spectra import interpolation_matrix
from specgen_addon.brdf.table import N_PHI_D, N_THETA_D, N_THETA_H, BRDFTable, theta_h_index
from specgen_addon.generate.refine import diffuse_floor_of, render_under
from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX, blur_image, rows_inside
from specgen_addon.generate.refine.holdout import block_folds
from specgen_addon.generate.refine.operator import PhotoOperator
from specgen_addon.model import shipped_weights
from specgen_addon.model.runtime.inference import evaluate_grid, get_backend, resample_square, sphere_crop
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.render.photo_reproduction import checked_photo, photo_scale, rgb_psnr
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]


@dataclass(frozen=True)
class LatentFitOptions:
    """Settings of :func:`fit_latent` (the defaults are the measured best, lab/notebook)."""

    steps: int = 100                   # Adam steps
    lr: float = 0.02                   # Adam's step size on z and c
    batch_pixels: int = 512            # sphere pixels rendered per step
    env_samples: int = 8               # environment samples per pixel in the cheap render
    refresh_every: int = 25            # steps between exact renders (defect correction, the check)
    fit_wavelengths_nm: tuple[float, ...] = (380.0, 460.0, 540.0, 620.0, 700.0, 780.0)
    eps_fraction: float = 0.05         # ε of the log loss, a fraction of the photo's level
    seed: int = 0                      # the pixel batches and the environment draw
    holdout: bool = False              # fit one half of the sphere's 8-px blocks, choose by the other
    keep_peak: bool = False            # θh nodes finer than the photo's pixel stay the network's

    def __post_init__(self) -> None:
        ints = {"steps": (1, 10_000), "batch_pixels": (16, 1_000_000), "env_samples": (1, 1024),
                "refresh_every": (1, 10_000), "seed": (0, 2 ** 32 - 1)}
        for name, (lo, hi) in ints.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise SpecGenError(f"latent fit: {name} must be an integer in [{lo}, {hi}], got {v!r}")
        for name in ("holdout", "keep_peak"):
            if not isinstance(getattr(self, name), bool):
                raise SpecGenError(f"latent fit: {name} must be true or false, got {getattr(self, name)!r}")
        for name in ("lr", "eps_fraction"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and 0 < v <= 1):
                raise SpecGenError(f"latent fit: {name} must be a number in (0, 1], got {v!r}")
        wl = np.asarray(self.fit_wavelengths_nm, dtype=np.float64)
        if wl.ndim != 1 or wl.size < 2 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
            raise SpecGenError("latent fit: fit_wavelengths_nm must be ≥ 2 increasing wavelengths (nm)")


@dataclass
class LatentFitResult:
    """The fitted table and the photo's self-reproduction (RGB PSNR, dB) before and after."""

    table: BRDFTable
    before_db: float
    after_db: float
    seconds: float
    blur_px: float = 0.0               # the photo's blur (Gaussian σ, px) the fit modelled
    improved: bool = True              # False: no latent reproduced the photo better; the network's table is kept
    best_step: int = 0                 # the step whose latent is returned (0: the encoder's)
    held_out_db: tuple[float, float] | None = None   # with ``holdout``: the judged half, before and after

    def summary(self) -> str:
        blur = f" (photo blur σ {self.blur_px:g} px modelled)" if self.blur_px > 0 else ""
        kept = "" if self.improved else " (no better: the network's table kept)"
        held = ("" if self.held_out_db is None
                else f" (held-out half {self.held_out_db[0]:.2f} → {self.held_out_db[1]:.2f} dB)")
        return (f"latent fit: self-reproduction {self.before_db:.2f} → {self.after_db:.2f} dB{held}{blur} "
                f"in {self.seconds:.1f} s{kept}")


def unresolved_theta_h_nodes(photo_size_px: int) -> int:
    """How many θh grid nodes lie below the photo's angular resolution: θh < 1/R rad, R = the
    sphere's radius in pixels (``photo_size_px`` / 2), the turn of the normal across one pixel at
    the sphere's centre. (For a 128-pixel crop: θh < 0.90°, nodes 0–8.)"""
    theta_res = 2.0 / float(photo_size_px)
    return int(np.ceil(theta_h_index(np.asarray(theta_res))))


def _runs(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Indices ``starts[0] … starts[0]+counts[0]−1, starts[1] …`` of consecutive runs, concatenated."""
    return np.repeat(starts - np.cumsum(np.r_[0, counts[:-1]]), counts) + np.arange(counts.sum())


class OperatorSamples:
    """Every sample of a :class:`~specgen_addon.generate.refine.operator.PhotoOperator`, sorted by pixel:
    its lookup's lower grid corner and offsets, and its radiance on the integration grid."""

    def __init__(self, op):
        pix, corner, frac, rad, env = [], [], [], [], []
        for g in op.groups:
            pix.append(g.pixel)
            corner.append(np.stack([g.ih, g.jd, g.kp], 1))
            frac.append(np.stack([g.th, g.td, g.tp], 1))
            rad.append((g.weights.astype(np.float64) @ g.radiance_basis).astype(np.float32))
            env.append(np.full(g.pixel.size, g.radiance_basis.shape[0] > 1))   # a light: one spectrum
        pix = np.concatenate(pix)
        order = np.argsort(pix, kind="stable")       # per pixel: its light samples, then the map's
        self.op = op
        self.pixel = pix[order]
        self.corner = np.concatenate(corner)[order].astype(np.int64)      # (S, 3)
        self.frac = np.concatenate(frac)[order].astype(np.float32)        # (S, 3)
        self.radiance = np.concatenate(rad)[order]                        # (S, Λr)
        is_env = np.concatenate(env)[order]
        self.start = np.searchsorted(self.pixel, np.arange(op.n_pixels + 1))
        self.n_env = np.bincount(self.pixel[is_env], minlength=op.n_pixels).astype(np.int64)
        self.env_start = self.start[1:] - self.n_env

    def draw(self, env_samples: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every light sample and ``env_samples`` environment samples per pixel, with replacement:
        (sample index, pixel, weight = the pixel's environment samples / ``env_samples``)."""
        P = self.op.n_pixels
        n_light = self.env_start - self.start[:-1]
        idx_l = _runs(self.start[:-1], n_light)
        pix_l = np.repeat(np.arange(P), n_light)
        has = self.n_env > 0
        u = rng.random((P, env_samples))
        idx_e = (self.env_start[:, None] + np.floor(u * self.n_env[:, None]).astype(np.int64))[has].ravel()
        pix_e = np.repeat(np.arange(P)[has], env_samples)
        w_e = np.repeat(self.n_env[has] / env_samples, env_samples)
        return (np.concatenate([idx_l, idx_e]), np.concatenate([pix_l, pix_e]),
                np.concatenate([np.ones(idx_l.size), w_e]).astype(np.float32))


class CheapRender:
    """The fit's per-step render: a fixed draw of samples, each at its nearest grid node, the
    network at a few bands interpolated onto the operator's integration grid."""

    def __init__(self, samples: OperatorSamples, env_samples: int, fit_wavelengths_nm, seed: int):
        import torch

        self.torch = torch
        op = samples.op
        idx, pixel, weight = samples.draw(env_samples, np.random.default_rng([seed, 1]))
        order = np.argsort(pixel, kind="stable")
        idx, pixel, weight = idx[order], pixel[order], weight[order]
        self.start = np.searchsorted(pixel, np.arange(op.n_pixels + 1))
        node = samples.corner[idx] + (samples.frac[idx] >= 0.5)
        node[:, 0] = np.minimum(node[:, 0], N_THETA_H - 1)
        node[:, 1] = np.minimum(node[:, 1], N_THETA_D - 1)
        node[:, 2] %= N_PHI_D
        self.node = (node[:, 0] * N_THETA_D + node[:, 1]) * N_PHI_D + node[:, 2]
        self.radiance = samples.radiance[idx] * weight[:, None]
        self.lambert = op.lambert.astype(np.float32)                         # (P, Λr)
        self.to_rgb = (op.exposure * op.to_rgb).astype(np.float32)           # (3, Λr)
        self.floor_interp = op.interp.astype(np.float32)                     # (Λ table, Λr)
        self.fit_interp = interpolation_matrix(fit_wavelengths_nm,
                                               op.render_wavelengths_nm).astype(np.float32)   # (Λfit, Λr)

    def rows(self, model, tables, pixels: np.ndarray, floor: np.ndarray, kept=None):
        """Linear sRGB rows ``(len(pixels), 3)`` of the network's ``tables`` (at the fit's bands)
        under the operator; ``floor`` (Λ table,) is the control variate the exact render uses.
        ``kept = (n, tables0)``: the θh nodes below ``n`` take their values from ``tables0``,
        without gradient (``keep_peak``)."""
        from specgen_addon.model.runtime.fast import head_at_nodes

        torch = self.torch
        lo, hi = self.start[pixels], self.start[pixels + 1]
        counts = hi - lo
        sel = _runs(lo, counts)
        local = torch.from_numpy(np.repeat(np.arange(pixels.size), counts))
        uniq, inv = np.unique(self.node[sel], return_inverse=True)
        i = torch.from_numpy(uniq // (N_THETA_D * N_PHI_D))
        j = torch.from_numpy((uniq // N_PHI_D) % N_THETA_D)
        k = torch.from_numpy(uniq % N_PHI_D)
        mu = model.cfg.mu
        r = head_at_nodes(model, tables, i, j, k)                                  # (U, Λfit) μ-law
        if kept is not None and kept[0] > 0:
            low = i < kept[0]
            if bool(low.any()):
                with torch.no_grad():
                    r0 = head_at_nodes(model, kept[1], i[low], j[low], k[low])
                r = r.clone()
                r[low] = r0
        f = torch.expm1(torch.clamp(r, min=0) * float(np.log1p(mu))) / mu          # sr⁻¹
        f = f[torch.from_numpy(inv.ravel())] @ torch.from_numpy(self.fit_interp)   # (n, Λr)
        floor_r = torch.from_numpy(np.asarray(floor, np.float32) @ self.floor_interp)
        contrib = (f - floor_r) * torch.from_numpy(self.radiance[sel])
        radiance = torch.zeros(pixels.size, f.shape[1]).index_add_(0, local, contrib)
        radiance = radiance + floor_r * torch.from_numpy(self.lambert[pixels])
        return radiance @ torch.from_numpy(self.to_rgb).T


def decode_table(backend, z, colour, wavelengths_nm: np.ndarray, cancel: CancelFn | None = None) -> np.ndarray:
    """The full table ``f_r`` (90, 90, 180, Λ) of a latent and colour, as :func:`generate_brdf`
    decodes the encoder's (the torch backend's fast grid path)."""
    from specgen_addon.model.runtime.fast import lambda_coords

    torch = backend.torch
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    u = lambda_coords(backend.model, wl)
    with torch.no_grad():
        tables = tuple(t.contiguous() for t in
                       backend.tables.tables_of(backend.model.generator(z, colour), u))
    return evaluate_grid(backend, tables, wl.size, cancel=cancel, decode_mu=backend.cfg.mu)


def fit_latent(image, photo: np.ndarray, lighting=None, weights=None, wavelengths_nm=None,
               options: LatentFitOptions = LatentFitOptions(), clip_level: float | np.ndarray | None = None,
               network_table: BRDFTable | None = None, progress: ProgressFn | None = None,
               cancel: CancelFn | None = None) -> LatentFitResult:
    """Fit the network's latent and colour to ``photo`` and return the table they decode to.

    Parameters
    ----------
    image
        What the network sees: a :class:`~specgen_addon.photo.sphere_image.SphereCrop` (or array) at the
        canonical white level (the photo times the lighting's network gain, as the pipeline does).
    photo
        The photo's linear sRGB sphere crop (S, S, 3), as :func:`specgen_addon.generate.refine.refine_brdf`
        takes it.
    lighting
        :class:`~specgen_addon.photo.photo_lighting.InputLighting` of the photo (default: canonical).
    weights
        ``.pt`` file; ``None`` picks the shipped network by how the sphere was cut.
    wavelengths_nm
        Bands of the returned table (nm; default 380–780 nm, 21 bands).
    clip_level
        Photo value at and above which a pixel counts as clipped (8/16-bit photos); ``None``: none.
    network_table
        The network's own table of ``image`` at ``wavelengths_nm``, if the caller has it (one
        decode fewer); it must be what :func:`~specgen_addon.model.runtime.inference.generate_brdf` returns.
    """
    import torch

    from specgen_addon.model.runtime.fast import lambda_coords

    t_start = time.perf_counter()
    lighting = lighting or InputLighting()
    photo = checked_photo(photo)
    crop = sphere_crop(image)
    if weights is None:
        weights = shipped_weights(crop.copied)
    be = get_backend(weights, "torch")
    if be.cfg.fusion != "aff":
        raise SpecGenError("the latent fit needs a network with AFF fusion")
    wl = np.asarray(DEFAULT_WAVELENGTHS_NM if wavelengths_nm is None else wavelengths_nm, dtype=np.float64)
    if network_table is not None and (network_table.values.shape[-1] != wl.size
                                      or not np.allclose(network_table.wavelengths, wl)):
        raise SpecGenError("latent fit: the network's table has other wavelengths than asked for")
    fit_wl = np.asarray(options.fit_wavelengths_nm, dtype=np.float64)
    if fit_wl[0] < be.cfg.lambda_min_nm - 1e-6 or fit_wl[-1] > be.cfg.lambda_max_nm + 1e-6:
        raise SpecGenError("latent fit: fit_wavelengths_nm fall outside the model's range")

    def report(f: float) -> None:
        if progress is not None:
            progress(min(max(f, 0.0), 1.0))

    def check_cancel() -> None:
        if cancel is not None and cancel():
            raise Cancelled("latent fit cancelled")

    scene = lighting.scene(photo.shape[0])
    exposure = lighting.image_exposure
    op = PhotoOperator(scene, wl, exposure, cancel=cancel)
    samples = OperatorSamples(op)
    cheap = CheapRender(samples, options.env_samples, fit_wl, options.seed)
    b = op.observe(photo)
    level = photo_scale(b)
    clipped = np.zeros(b.shape[0], dtype=bool) if clip_level is None else np.any(b >= clip_level, axis=1)
    if np.count_nonzero(~clipped) < 16:
        raise SpecGenError("latent fit: fewer than 16 unclipped sphere pixels in the photo")
    target = torch.from_numpy(b.astype(np.float32))
    eps = options.eps_fraction * level

    model = be.model
    x = torch.from_numpy(resample_square(crop.image, be.cfg.image_size)[None].astype(np.float32))
    threads = torch.get_num_threads()
    try:
        with torch.no_grad():
            z0 = model.latent(x)
            c0 = model.encoder.colour(x)
        z = z0.clone().requires_grad_(True)
        colour = c0.clone().requires_grad_(True)
        opt = torch.optim.Adam([z, colour], lr=options.lr)
        u_fit = lambda_coords(model, fit_wl)
        rng = np.random.default_rng([options.seed, 2])
        n_refresh = -(-options.steps // options.refresh_every) + 1     # and the last step's
        decode_share = 0.6 / n_refresh            # progress: decodes 60 %, steps 40 %
        done = [0.0]

        sigma = [None]
        n_kept = unresolved_theta_h_nodes(photo.shape[0]) if options.keep_peak else 0
        kept = None
        if n_kept:
            with torch.no_grad():
                kept = (n_kept, tuple(t.detach() for t in be.tables.tables_of(model.generator(z0, c0), u_fit)))
        network_values = [None]

        def exact(zz, cc, table: BRDFTable | None = None) -> tuple[np.ndarray, np.ndarray, BRDFTable]:
            """Decoded table, its control-variate floor and its exact photo rows at (zz, cc),
            blurred as the photo is (σ chosen on the first call); with ``keep_peak`` the θh nodes
            below the photo's resolution are the network's (the first call's table)."""
            if table is None:
                values = decode_table(be, zz, cc, wl, cancel=cancel)
                if n_kept and network_values[0] is not None:
                    values[:n_kept] = network_values[0][:n_kept]
                table = BRDFTable(values, wl)
            if network_values[0] is None:
                network_values[0] = table.values
            torch.set_num_threads(threads)
            image_ = render_under(table, scene, exposure)
            if sigma[0] is None:
                sigma[0] = 0.0 if crop.copied else _photo_blur(op, image_, b, clipped, level)
            rows = op.observe(blur_image(image_, sigma[0]) if sigma[0] > 0 else image_)
            done[0] += decode_share
            report(done[0])
            return rows, diffuse_floor_of(table), table

        def cheap_all(zz, cc, floor) -> np.ndarray:
            with torch.no_grad():
                tables = be.tables.tables_of(model.generator(zz, cc), u_fit)
                return np.concatenate([cheap.rows(model, tables, np.arange(s, min(s + 2048, op.n_pixels)),
                                                  floor, kept).numpy() for s in range(0, op.n_pixels, 2048)])

        seen = usable = best = None
        lr = options.lr
        for step in range(options.steps + 1):
            check_cancel()
            if step % options.refresh_every == 0 or step == options.steps:
                # the exact photo at the current latent: keep it if it reproduces the photo better
                # than the best so far; else go back to the best with half the step size
                zr, cr = torch.relu(z.detach()), colour.detach()
                rows, floor, table = exact(zr, cr, network_table if step == 0 else None)
                if seen is None:
                    seen = rows_inside(op.shape, op.pixel_ids, sigma[0], clipped)
                    judge = seen.copy()
                    if options.holdout:     # fit one half of a checkerboard of blocks, judge by the other
                        fold = block_folds(op.shape, op.pixel_ids)
                        judge &= fold == 1
                        usable = np.flatnonzero(seen & (fold == 0))
                    else:
                        usable = np.flatnonzero(seen)
                    if usable.size < 16 or np.count_nonzero(judge) < 16:
                        raise SpecGenError("latent fit: fewer than 16 unclipped pixels inside the sphere")
                score = rgb_psnr(b[judge], rows[judge], level)
                whole = rgb_psnr(b[seen], rows[seen], level)
                if best is None:
                    before, judged_before = whole, score
                if best is None or score > best["db"]:
                    best = {"db": score, "whole": whole, "z": zr.clone(), "colour": cr.clone(), "table": table,
                            "floor": floor, "step": step, "defect": None}
                elif step < options.steps:
                    with torch.no_grad():
                        z.copy_(best["z"])
                        colour.copy_(best["colour"])
                    lr *= 0.5
                    opt = torch.optim.Adam([z, colour], lr=lr)
                if step == options.steps:
                    break
                floor = best["floor"]
                if best["defect"] is None:
                    best["defect"] = torch.from_numpy(
                        (rows - cheap_all(best["z"], best["colour"], floor)).astype(np.float32))
                defect = best["defect"]
            pixels = np.sort(rng.choice(usable, size=min(options.batch_pixels, usable.size), replace=False))
            torch.set_num_threads(1)     # the gathers' gradients sum in a fixed order: bit-repeatable
            tables = be.tables.tables_of(model.generator(z, colour), u_fit)
            rgb = cheap.rows(model, tables, pixels, floor, kept) + defect[pixels]
            loss = ((torch.log(eps + torch.clamp(rgb, min=0.0)) - torch.log(eps + target[pixels])) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            with torch.no_grad():
                z.clamp_(min=0.0)
            done[0] += 0.4 / options.steps
            report(done[0])
    finally:
        torch.set_num_threads(threads)
    table, after, improved = best["table"], best["whole"], best["step"] > 0
    table.metadata = {**table.metadata, "source": "specgen", "backend": "torch", "weights": str(weights),
                      "input_sphere": "copied" if crop.copied else "resampled",
                      "description": "SpecGen prediction, latent fitted to the photo" if improved
                      else "SpecGen prediction (the latent fit did not reproduce the photo better)",
                      "latent_fit": f"best at step {best['step']} of {options.steps}, self-reproduction "
                                    f"{before:.2f} -> {after:.2f} dB" + ("" if improved else ", network's table kept")
                                    + (f", θh nodes below {n_kept} the network's" if n_kept else "")}
    report(1.0)
    return LatentFitResult(table, float(before), float(after), time.perf_counter() - t_start, sigma[0], improved,
                           best["step"], (float(judged_before), float(best["db"])) if options.holdout else None)


def _photo_blur(op, image: np.ndarray, photo_rows: np.ndarray, clipped: np.ndarray, level: float) -> float:
    """The blur σ (px) of :data:`~specgen_addon.generate.refine.blur.BLUR_CANDIDATES_PX` under which the
    network's own render ``image`` reproduces the photo best, on the pixels every candidate keeps."""
    common = rows_inside(op.shape, op.pixel_ids, max(BLUR_CANDIDATES_PX), clipped)
    if not np.any(common):
        return 0.0
    scores = [rgb_psnr(photo_rows[common], op.observe(blur_image(image, s) if s > 0 else image)[common], level)
              for s in BLUR_CANDIDATES_PX]
    return float(BLUR_CANDIDATES_PX[int(np.nanargmax(scores))])
