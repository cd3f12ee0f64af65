"""The photo as a linear function of the BRDF table: one operator per input lighting.

Rendering is linear in the BRDF. Under fixed lighting and camera the reference renderer
(:class:`specgen_addon.render.Scene`) estimates a pixel as

    L_p(λ) = Σ_s f(ω_s, ω_o,p, λ) R_s(λ)  +  c(λ) · Δ_p(λ),

a sum over the pixel's light and environment samples ``s`` (incident direction ``ω_s``, radiance
times MIS weight ``R_s``) plus the control variate's exact diffuse term. With ``f`` looked up
trilinearly in the table, every sample is a fixed weighted sum of eight table cells. This module
keeps those samples (their cells, weights and radiance) once per lighting, so that the design
matrix of the correction basis (:mod:`specgen_addon.refine.basis`) is one pass of gathers and
segmented sums over them — the same sample directions the renderer uses, so a photo rendered by it
is reproduced without Monte-Carlo mismatch. numpy only: it runs inside a stock Blender.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import spectra
from ..errors import Cancelled, SpecGenError
from ..rusinkiewicz import half_diff_from_io
from ..table import N_PHI_D, N_THETA_D, N_THETA_H, phi_d_index, theta_d_index, theta_h_index
from .basis import CorrectionBasis, sparse_hats

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]

#: Pixels seen closer to grazing than this (cos θo < 0.15, θo > 81°) are not observed: in a photo
#: the outermost ring of the silhouette mixes sphere and background (antialiasing, the circle fit
#: of the loader), and its values hinge on a BRDF's most extreme grazing entries. About 3% of the
#: sphere's pixels at 128², a one-pixel ring.
RIM_COS = 0.15


@dataclass
class SampleGroup:
    """Samples sharing one radiance basis: ``R_s(λ) = weights[s] @ radiance_basis``.

    ``pixel`` indexes the operator's observed pixels; ``ih, jd, kp`` are the lower grid corners
    (θh, θd, φd) and ``th, td, tp`` the fractional offsets of the trilinear lookup.
    """

    pixel: np.ndarray         # (S,) int32
    ih: np.ndarray            # (S,) int16
    jd: np.ndarray            # (S,) int16
    kp: np.ndarray            # (S,) int16
    th: np.ndarray            # (S,) float32
    td: np.ndarray            # (S,) float32
    tp: np.ndarray            # (S,) float32
    weights: np.ndarray       # (S, K) float32
    radiance_basis: np.ndarray  # (K, Λ)


def _corners(x: np.ndarray, n: int, periodic: bool) -> tuple[np.ndarray, np.ndarray]:
    if periodic:
        x = np.mod(x, n)
        i0 = np.floor(x).astype(np.int64)
        return i0 % n, (x - i0).astype(np.float32)
    x = np.clip(x, 0.0, n - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    return i0, (x - i0).astype(np.float32)


def _group(pixel: np.ndarray, wi: np.ndarray, wo: np.ndarray, weights: np.ndarray,
           radiance_basis: np.ndarray) -> SampleGroup:
    th, td, pd = half_diff_from_io(np.asarray(wi, np.float64), np.asarray(wo, np.float64))
    ih, fh = _corners(theta_h_index(th), N_THETA_H, False)
    jd, fd = _corners(theta_d_index(td), N_THETA_D, False)
    kp, fp = _corners(phi_d_index(pd), N_PHI_D, True)
    return SampleGroup(pixel.astype(np.int32), ih.astype(np.int16), jd.astype(np.int16),
                       kp.astype(np.int16), fh, fd, fp, np.asarray(weights, np.float32),
                       np.asarray(radiance_basis, np.float64))


def render_grid(wavelengths_nm: np.ndarray) -> np.ndarray:
    """Wavelengths (nm) a photo of a table with these bands is integrated on: the bands themselves
    and the default 21-band grid's wavelengths that fall inside them."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    default = spectra.DEFAULT_WAVELENGTHS_NM
    inside = default[(default > wl[0] + 1e-6) & (default < wl[-1] - 1e-6)]
    return np.unique(np.concatenate([wl, inside]))


class PhotoOperator:
    """Linear map from a BRDF table to the photo's pixels under one lighting.

    Parameters
    ----------
    scene
        A prepared :class:`~specgen_addon.render.Scene` (the input's sphere and lighting).
    wavelengths_nm
        The table's wavelengths (nm). Light and camera are integrated on :func:`render_grid` (the
        table's bands plus the default 21-band grid inside their range, the table interpolated
        linearly in λ as the renderer does), so a coarse table is not scored through a coarse
        CMF sum.
    exposure
        Photo value per unit radiance.
    """

    def __init__(self, scene, wavelengths_nm: np.ndarray, exposure: float,
                 progress: ProgressFn | None = None, cancel: CancelFn | None = None):
        self.wavelengths_nm = np.asarray(wavelengths_nm, dtype=np.float64)
        wl = render_grid(self.wavelengths_nm)
        #: (Λr,) wavelengths (nm) light and camera are integrated on; ``interp`` (Λ, Λr) maps table
        #: spectra onto them (linear in λ, as :meth:`BRDFTable.eval` interpolates)
        self.render_wavelengths_nm = wl
        eye = np.eye(self.wavelengths_nm.size)
        self.interp = np.stack([np.interp(wl, self.wavelengths_nm, eye[c]) for c in range(eye.shape[0])])
        self.exposure = float(exposure)
        self.shape = scene.geometry.shape
        blocks = scene._prepare()
        normals = scene.geometry.normals.reshape(-1, 3)
        ids = np.concatenate([b.ids for b in blocks])
        ids = ids[normals[ids] @ scene.camera_dir >= RIM_COS]
        #: flat image indices of the observed pixels (sphere pixels facing the camera, off the rim)
        self.pixel_ids = ids
        compact = np.full(self.shape[0] * self.shape[1], -1, dtype=np.int64)
        compact[ids] = np.arange(ids.size)
        #: (3, Λ) spectral radiance → linear sRGB (the renderer's CMF projection, D65 white)
        self.to_rgb = spectra.spectral_to_linear_srgb(np.eye(wl.size), wl).T
        env_u = None if scene.environment is None else scene.environment.spectral_basis(wl)
        lambert = np.zeros((ids.size, wl.size))     # response of f ≡ 1: irradiance + lights
        self.groups: list[SampleGroup] = []
        light_spectra = [l.spectrum(wl)[None, :] for l in scene.lights]
        for n, blk in enumerate(blocks):
            if cancel is not None and cancel():
                raise Cancelled("refinement cancelled")
            pix = compact[blk.ids]                     # −1: a rim pixel, not observed
            for wi_l, spec in zip(blk.light_wi, light_spectra):
                lit = (wi_l[:, 2] > 0) & (pix >= 0)
                if np.any(lit):
                    cos = wi_l[lit, 2:3]
                    self.groups.append(_group(pix[lit], wi_l[lit], blk.wo_local[lit], cos, spec))
                    lambert[pix[lit]] += cos * spec
            if blk.env is not None:
                e = blk.env
                seen = pix >= 0
                lambert[pix[seen]] += e.irradiance_rgb[seen] @ env_u
                s_seen = seen[e.pixel]
                self.groups.append(_group(pix[e.pixel[s_seen]], e.wi_local[s_seen],
                                          blk.wo_local[e.pixel[s_seen]], e.weight_rgb[s_seen], env_u))
            if progress is not None:
                progress((n + 1) / len(blocks))
        #: (P, Λ) radiance of a constant BRDF of 1 sr⁻¹ at each pixel (exact: irradiance, lights)
        self.lambert = lambert

    @property
    def n_pixels(self) -> int:
        return int(self.pixel_ids.size)

    @property
    def n_samples(self) -> int:
        return int(sum(g.pixel.size for g in self.groups))

    def image(self, rgb_rows: np.ndarray) -> np.ndarray:
        """Observed-pixel rows (P, 3) back to an (H, W, 3) image (zeros elsewhere)."""
        out = np.zeros((self.shape[0] * self.shape[1], 3))
        out[self.pixel_ids] = rgb_rows
        return out.reshape(*self.shape, 3)

    def observe(self, image: np.ndarray) -> np.ndarray:
        """The photo's observed pixels (P, 3) from an (H, W, 3) image of this operator's size."""
        image = np.asarray(image, dtype=np.float64)
        if image.shape != (*self.shape, 3):
            raise SpecGenError(f"photo is {image.shape[:2]}, the lighting operator {self.shape}")
        return image.reshape(-1, 3)[self.pixel_ids]

    # ------------------------------------------------------------------------- design matrices
    def lambert_design(self, spectrum: np.ndarray, spectral_hats: np.ndarray) -> np.ndarray:
        """(P, 3, L): photo of the Lambertian-like BRDF ``spectrum(λ) s_l(λ)`` per spectral hat."""
        on_grid = self.interp.T @ (np.asarray(spectrum)[:, None] * spectral_hats)     # (Λr, L)
        per_band = self.lambert[:, :, None] * on_grid[None]
        return self.exposure * np.einsum("cw,pwl->pcl", self.to_rgb, per_band, optimize=True)

    def lobe_design(self, values: np.ndarray, floor: np.ndarray, basis: CorrectionBasis,
                    progress: ProgressFn | None = None, cancel: CancelFn | None = None) -> np.ndarray:
        """(P, 3, Na, Nb, L): photo of ``(values − floor) · h_a(θh) g_b(θd) s_l(λ)`` per hat triple.

        ``values`` is the table (90, 90, 180, Λ), ``floor`` its diffuse floor ``c`` (Λ,). The hats
        are applied at the grid nodes, before the trilinear lookup, exactly as the corrected table
        is built — so the design reproduces the renderer's lookups of that table.
        """
        na, nb, nl = basis.shape
        s_hats = basis.spectral_hats(self.wavelengths_nm)
        h_idx, h_val = sparse_hats(basis.theta_h_hats())
        d_idx, d_val = sparse_hats(basis.theta_d_hats())
        flat = values.reshape(-1, values.shape[-1])
        floor32 = np.asarray(floor, np.float32)
        # per spectral hat l: table bands × s_l → render grid (Λ, Λr), then radiance, then → RGB
        to_grid = [(s_hats[:, l:l + 1] * self.interp).astype(np.float32) for l in range(nl)]
        to_rgb = self.to_rgb.T.astype(np.float32)                                  # (Λr, 3)
        n_bins = self.n_pixels * na * nb
        design = np.zeros((n_bins, 3 * nl))
        total = max(self.n_samples, 1)
        done = 0
        for g in self.groups:
            for start in range(0, g.pixel.size, 65536):
                if cancel is not None and cancel():
                    raise Cancelled("refinement cancelled")
                sl = slice(start, start + 65536)
                radiance = (g.weights[sl].astype(np.float64) @ g.radiance_basis).astype(np.float32)
                ih, jd, kp = g.ih[sl].astype(np.int64), g.jd[sl].astype(np.int64), g.kp[sl].astype(np.int64)
                th, td, tp = g.th[sl], g.td[sl], g.tp[sl]
                kp1 = (kp + 1) % N_PHI_D
                pix = g.pixel[sl].astype(np.int64)
                idx_parts, val_parts = [], []
                for di, wi in ((0, 1 - th), (1, th)):
                    i = ih + di
                    for dj, wj in ((0, 1 - td), (1, td)):
                        j = jd + dj
                        base = (i * N_THETA_D + j) * N_PHI_D
                        q = (1 - tp)[:, None] * flat[base + kp] + tp[:, None] * flat[base + kp1]
                        q -= floor32
                        rgb = np.empty((q.shape[0], 3, nl), dtype=np.float32)
                        for l in range(nl):
                            rgb[:, :, l] = ((q @ to_grid[l]) * radiance) @ to_rgb
                        rgb = rgb.reshape(q.shape[0], 3 * nl)     # (S, 3L), c-major
                        w_ij = wi * wj
                        for ka in range(h_idx.shape[1]):
                            a = h_idx[i, ka]
                            wa = w_ij * h_val[i, ka]
                            for kb in range(d_idx.shape[1]):
                                w = wa * d_val[j, kb]
                                keep = w > 0
                                b = d_idx[j, kb]
                                if keep.all():                   # (no copies for the usual case)
                                    idx_parts.append((pix * na + a) * nb + b)
                                    val_parts.append(rgb * w[:, None])
                                elif keep.any():
                                    idx_parts.append(((pix * na + a) * nb + b)[keep])
                                    val_parts.append(rgb[keep] * w[keep, None])
                idx = np.concatenate(idx_parts)
                vals = np.concatenate(val_parts)                  # (M, 3L), C-contiguous
                # one scatter-add for all 3L columns: entry (m, col) goes to bin idx[m]·3L + col, in
                # the same order per bin as one bincount per column (the same sums, bit for bit),
                # over the bins this chunk reaches only (a chunk's samples are a few neighbouring
                # pixels'; the others would gain exact zeros)
                lo, hi = int(idx.min()), int(idx.max()) + 1
                cells = ((idx - lo)[:, None] * (3 * nl) + np.arange(3 * nl)).ravel()
                design[lo:hi] += np.bincount(cells, weights=vals.ravel(),
                                             minlength=(hi - lo) * 3 * nl).reshape(hi - lo, 3 * nl)
                done += radiance.shape[0]
                if progress is not None:
                    progress(done / total)
        design = design.reshape(self.n_pixels, na, nb, 3, nl).transpose(0, 3, 1, 2, 4)
        return self.exposure * design
