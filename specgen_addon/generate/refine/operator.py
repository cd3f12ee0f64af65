"""The photo as a linear function of the BRDF table: one operator per input lighting.

Rendering is linear in the BRDF. Under fixed lighting and camera the reference renderer
(:class:`specgen_addon.render.Scene`) estimates a pixel as

    L_p(λ) = Σ_s f(ω_s, ω_o,p, λ) R_s(λ)  +  c(λ) · Δ_p(λ),

a sum over the pixel's light and environment samples ``s`` (incident direction ``ω_s``, radiance
times MIS weight ``R_s``) plus the control variate's exact diffuse term. With ``f`` looked up
trilinearly in the table, every sample is a fixed weighted sum of eight table cells. This module
keeps those samples (their cells, weights and radiance) once per lighting, so that the design
matrix of the correction basis (:mod:`specgen_addon.generate.refine.basis`) is one pass of gathers and
segmented sums over them — the same sample directions the renderer uses, so a photo rendered by it
is reproduced without Monte-Carlo mismatch. numpy only: it runs inside a stock Blender.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.brdf.rusinkiewicz import half_diff_from_io
from specgen_addon.brdf.table import N_PHI_D, N_THETA_D, N_THETA_H, phi_d_index, theta_d_index, theta_h_index
from specgen_addon.generate.refine.basis import CorrectionBasis

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]
#: (rows, group, radiance (S, Λr), to_rgb_l) → the samples' four corner photos, each (S, 3L)
CornerPhotos = Callable[[slice, "SampleGroup", np.ndarray, Callable], list]

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
        self.interp = spectra.interpolation_matrix(self.wavelengths_nm, wl)
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
        flat = values.reshape(-1, values.shape[-1])
        floor32 = np.asarray(floor, np.float32)

        def corner_rgb(rows: slice, g: SampleGroup, radiance: np.ndarray, to_rgb_l) -> list:
            """(S, 3L) photo of each of the sample's four (θh, θd) corners, interpolated in φd."""
            ih, jd, kp = g.ih[rows].astype(np.int64), g.jd[rows].astype(np.int64), g.kp[rows].astype(np.int64)
            tp = g.tp[rows][:, None]
            kp1 = (kp + 1) % N_PHI_D
            out = []
            for di in (0, 1):
                for dj in (0, 1):
                    base = ((ih + di) * N_THETA_D + jd + dj) * N_PHI_D
                    q = flat[base + kp]
                    q += tp * (flat[base + kp1] - q)
                    q -= floor32
                    out.append(to_rgb_l(q, radiance))
            return out

        return self._hat_design(basis, corner_rgb, progress, cancel)

    def added_design(self, basis: CorrectionBasis, progress: ProgressFn | None = None,
                     cancel: CancelFn | None = None) -> np.ndarray:
        """(P, 3, Na, Nb, L): photo of the BRDF ``h_a(θh) g_b(θd) s_l(λ)`` (sr⁻¹) per hat triple.

        The lobe design of the constant table 1 with no floor: every corner of a lookup holds the
        same spectrum, so each sample is projected to RGB once."""
        ones = np.ones((1, self.wavelengths_nm.size), np.float32)

        def corner_rgb(rows: slice, g: SampleGroup, radiance: np.ndarray, to_rgb_l) -> list:
            return [to_rgb_l(ones, radiance)] * 4

        return self._hat_design(basis, corner_rgb, progress, cancel)

    def _hat_design(self, basis: CorrectionBasis, corner_rgb: CornerPhotos, progress: ProgressFn | None,
                    cancel: CancelFn | None) -> np.ndarray:
        """Scatter every sample's photo into the (pixel, θh hat, θd hat) bins it reaches.

        ``corner_rgb(rows, group, radiance, to_rgb_l)`` gives the samples' (S, 3L) photos at their
        four lookup corners (θh, θd) = (0, 0), (0, 1), (1, 0), (1, 1). The hats' knots are grid
        nodes, so both θh corners of a lookup lie in one knot interval ``[k_m, k_m+1]`` and reach
        the same two hats ``m, m + 1`` (and likewise in θd): each sample adds to four bins, its
        corners' photos weighted by trilinear weight × hat value at the corner.
        """
        na, nb, nl = basis.shape
        s_hats = basis.spectral_hats(self.wavelengths_nm)
        h_seg, h_lo, h_hi = _hat_slots(basis.theta_h_hats(), basis.theta_h_knots)
        d_seg, d_lo, d_hi = _hat_slots(basis.theta_d_hats(), basis.theta_d_knots)
        # per spectral hat l: table bands × s_l → render grid (Λ, Λr), then radiance, then → RGB
        to_grid = [(s_hats[:, l:l + 1] * self.interp).astype(np.float32) for l in range(nl)]
        to_rgb = self.to_rgb.T.astype(np.float32)                                  # (Λr, 3)

        def to_rgb_l(q: np.ndarray, radiance: np.ndarray) -> np.ndarray:
            rgb = np.empty((radiance.shape[0], 3, nl), dtype=np.float32)
            for l in range(nl):
                rgb[:, :, l] = ((q @ to_grid[l]) * radiance) @ to_rgb
            return rgb.reshape(radiance.shape[0], 3 * nl)                   # (S, 3L), c-major

        width = 3 * nl
        design = np.zeros((self.n_pixels * na * nb, width))
        total = max(self.n_samples, 1)
        done = 0
        for g in self.groups:
            for start in range(0, g.pixel.size, 65536):
                if cancel is not None and cancel():
                    raise Cancelled("refinement cancelled")
                rows = slice(start, start + 65536)
                radiance = (g.weights[rows].astype(np.float64) @ g.radiance_basis).astype(np.float32)
                corners = corner_rgb(rows, g, radiance, to_rgb_l)       # [(0,0), (0,1), (1,0), (1,1)]
                ih, jd = g.ih[rows].astype(np.int64), g.jd[rows].astype(np.int64)
                th, td = g.th[rows], g.td[rows]
                # weight of corner d ∈ {0, 1} for hat slot t: trilinear weight × hat value there
                wh = [((1 - th) * h_lo[ih, t], th * h_hi[ih, t]) for t in range(h_lo.shape[1])]
                wd = [((1 - td) * d_lo[jd, t], td * d_hi[jd, t]) for t in range(d_lo.shape[1])]
                pix = g.pixel[rows].astype(np.int64)
                idx_parts, val_parts = [], []
                for ta, (wh0, wh1) in enumerate(wh):
                    # Σ over the θh corner first: (S, 3L) per θd corner
                    by_d = [corners[0 + dj] * wh0[:, None] + corners[2 + dj] * wh1[:, None] for dj in (0, 1)]
                    a = h_seg[ih] + ta
                    for tb, (wd0, wd1) in enumerate(wd):
                        val_parts.append(by_d[0] * wd0[:, None] + by_d[1] * wd1[:, None])
                        idx_parts.append((pix * na + a) * nb + d_seg[jd] + tb)
                idx = np.concatenate(idx_parts)
                vals = np.concatenate(val_parts)                  # (M, 3L), C-contiguous
                # one scatter-add for all 3L columns (entry (m, col) → bin idx[m]·3L + col), over
                # the bins this chunk reaches only (a chunk's samples are a few neighbouring pixels')
                lo, hi = int(idx.min()), int(idx.max()) + 1
                cells = ((idx - lo)[:, None] * width + np.arange(width)).ravel()
                design[lo:hi] += np.bincount(cells, weights=vals.ravel(),
                                             minlength=(hi - lo) * width).reshape(hi - lo, width)
                done += radiance.shape[0]
                if progress is not None:
                    progress(done / total)
        design = design.reshape(self.n_pixels, na, nb, 3, nl).transpose(0, 3, 1, 2, 4)
        return self.exposure * design


def _hat_slots(hats: np.ndarray, knots) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per lower grid node i (0 … n − 2): the first hat m of the knot interval holding [i, i + 1],
    and the hat values of slots m, m + 1 at node i (``lo``) and node i + 1 (``hi``), (n − 1, T)
    with T = 2 (1 for a single hat)."""
    n, n_hats = hats.shape
    nodes = np.arange(n - 1)
    seg = np.clip(np.searchsorted(np.asarray(knots, np.float64), nodes, side="right") - 1, 0, max(n_hats - 2, 0))
    slots = min(n_hats, 2)
    lo = np.stack([hats[nodes, seg + t] for t in range(slots)], axis=1).astype(np.float32)
    hi = np.stack([hats[nodes + 1, seg + t] for t in range(slots)], axis=1).astype(np.float32)
    if not np.allclose(lo.sum(axis=1), 1.0) or not np.allclose(hi.sum(axis=1), 1.0):
        raise SpecGenError("internal: hat knots must be grid nodes (two hats per knot interval)")
    return seg, lo, hi
