"""SpecGen evaluated directly at a renderer's queries, without tabulating the 90×90×180×Λ grid.

:func:`specgen_addon.model.runtime.inference.generate_brdf` fills the whole MERL grid (~10 s on two cores); a
distant-light render only needs the BRDF at a few hundred thousand (θh, θd, φd, λ) points. The
ablation arms are scored this way (the same network function and the same μ-law decoding as the
table, without its grid interpolation), which makes scoring four arms on every test material cheap.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from specgen_addon.brdf.rusinkiewicz import half_diff_from_io
from specgen_addon.brdf.table import mu_law_decode_inplace
from specgen_addon.model.runtime.inference import network_input

#: Points per network call (bounded memory).
CHUNK = 262_144


class NetworkBRDF:
    """``eval(wi, wo, λ) -> (N, Λ)`` f_r in sr⁻¹ of the SpecGen prediction for one input image.

    Parameters
    ----------
    weights
        ``.pt`` weights file.
    image
        Linear-sRGB sphere image (H×W×3), as for :func:`specgen_addon.model.runtime.inference.generate_brdf`.
    """

    def __init__(self, weights: str | Path, image: np.ndarray):
        import torch

        from specgen_addon.model import load_weights

        self.torch = torch
        self.model = load_weights(weights).eval()
        x = network_input(image, self.model.cfg.image_size).astype(np.float32)
        with torch.no_grad():
            self.planes = self.model.planes(torch.from_numpy(x))

    def eval(self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
        torch = self.torch
        wi = np.asarray(wi, dtype=np.float64).reshape(-1, 3)
        wo = np.asarray(wo, dtype=np.float64).reshape(-1, 3)
        wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
        th, td, pd = half_diff_from_io(wi, wo)
        n, k = th.shape[0], wl.size
        pts = [np.repeat(a, k).astype(np.float32) for a in (th, td, pd)] + [np.tile(wl, n).astype(np.float32)]
        rp = np.empty(n * k, dtype=np.float32)
        with torch.no_grad():
            for s in range(0, n * k, CHUNK):
                q = [torch.from_numpy(p[s:s + CHUNK])[None] for p in pts]
                rp[s:s + CHUNK] = self.model.query(self.planes, *q)[0].numpy()
        mu_law_decode_inplace(rp, self.model.cfg.mu)                   # as generate_brdf decodes
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        return rp.reshape(n, k).astype(np.float64) * above[:, None]
