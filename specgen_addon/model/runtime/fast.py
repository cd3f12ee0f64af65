"""Fast evaluation of SpecGen on the full MERL grid × a wavelength grid (used by inference).

The structure of the network is exploited, exactly (no approximation):

* the projector is bilinear and the AFF statistic ``s = Σ_k m_k·f_k + b`` (per-branch conv then
  GAP) and the MLP's first layer ``W1·f_u = Σ_k w_k W1·f_k`` are linear in the features, so the
  linear parts are applied once per plane *texel* (``W1·F``, ``m_k·F``) and then resampled onto
  the grid;
* the grid is a tensor product, so every plane is resampled once onto its two grid axes:
  spatial planes do not depend on λ and spectral planes not on the third angle;
* per grid point only the cheap remainder runs: ``s`` as a sum of six table entries, the
  ``d = 32`` expansion, softmax, the weighted sum of six ``h1``-vectors, and layers 2–3.

:class:`GridTables` (image + λ coordinates -> six tables) and :class:`GridHead` (a block of
table rows -> r') are plain modules, so the same code runs in torch and, exported, in ONNX.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from specgen_addon.brdf.table import N_PHI_D, N_THETA_D, N_THETA_H
from specgen_addon.model.planes import PLANE_AXES, PLANE_NAMES
from specgen_addon.model.specgen import SpecGen


def merl_axis_coords() -> dict[str, torch.Tensor]:
    """Normalised plane coordinates of the MERL grid samples (θh is √-warped: index/90)."""
    return {"theta_h": 2.0 * torch.arange(N_THETA_H, dtype=torch.float32) / N_THETA_H - 1.0,
            "theta_d": 2.0 * torch.arange(N_THETA_D, dtype=torch.float32) / N_THETA_D - 1.0,
            "phi_d": 2.0 * torch.arange(N_PHI_D, dtype=torch.float32) / N_PHI_D - 1.0}


def lambda_coords(model: SpecGen, wavelengths_nm) -> torch.Tensor:
    """Normalised λ plane coordinates of wavelengths in nm (:meth:`Config.lambda_coordinates`)."""
    return torch.from_numpy(model.cfg.lambda_coordinates(wavelengths_nm))


def _resample(plane: torch.Tensor, u_rows: torch.Tensor, u_cols: torch.Tensor) -> torch.Tensor:
    """Bilinear resample ``(1, ch, R, K)`` on the tensor grid rows × cols -> ``(nr, nc, ch)``."""
    gy = u_rows[:, None].expand(-1, u_cols.shape[0])
    gx = u_cols[None, :].expand(u_rows.shape[0], -1)
    grid = torch.stack([gx, gy], dim=-1)[None]
    out = F.grid_sample(plane, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return out[0].permute(1, 2, 0)


class GridTables(nn.Module):
    """Image ``(1, 3, S, S)`` and λ coordinates ``(Λ,)`` -> the six per-axis tables.

    AFF: each table holds ``[W1·f, m_k·f]`` (``h1 + 1`` channels) for its plane; Hadamard: ``f``.
    Shapes: d1 (90, 90), d2 (90, 180), d3 (90, 180), e1 (90, Λ), e2 (90, Λ), e3 (180, Λ).
    """

    def __init__(self, model: SpecGen):
        super().__init__()
        self.model = model
        self.aff = model.cfg.fusion == "aff"
        for k, v in merl_axis_coords().items():
            self.register_buffer(f"u_{k}", v, persistent=False)

    def derived_planes(self, planes: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        if not self.aff:
            return planes
        w1 = self.model.mapping.fc1.weight                       # (h1, C)
        m, _ = self.model.fusion.gap_functionals()               # (6, C)
        out = {}
        for k, name in enumerate(PLANE_NAMES):
            rows = torch.cat([w1, m[k:k + 1]], dim=0)            # (h1 + 1, C)
            out[name] = torch.einsum("oc,bcrk->bork", rows, planes[name])
        return out

    def forward(self, image: torch.Tensor, u_lambda: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return self.tables_of(self.model.planes(image), u_lambda)

    def tables_of(self, planes: dict[str, torch.Tensor], u_lambda: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The six tables of given planes (differentiable: the latent fit decodes its own planes)."""
        planes = self.derived_planes(planes)
        u = {"theta_h": self.u_theta_h, "theta_d": self.u_theta_d, "phi_d": self.u_phi_d,
             "lambda": u_lambda}
        return tuple(_resample(planes[n], u[PLANE_AXES[n][0]], u[PLANE_AXES[n][1]]) for n in PLANE_NAMES)


class GridHead(nn.Module):
    """Rows of the six tables -> r' ``(nh, nd, 180, Λ)`` (μ-law space).

    Inputs: ``t1 (nh, nd, ch)``, ``t2 (nh, 180, ch)``, ``t3 (nd, 180, ch)``, ``t4 (nh, Λ, ch)``,
    ``t5 (nd, Λ, ch)``, ``t6 (180, Λ, ch)`` for a block of θh rows (nh) and θd rows (nd).
    """

    def __init__(self, model: SpecGen):
        super().__init__()
        self.model = model
        self.aff = model.cfg.fusion == "aff"

    def forward(self, t1, t2, t3, t4, t5, t6) -> torch.Tensor:
        # Broadcast each table to (nh, nd, np, nl, ch).
        b = (t1[:, :, None, None], t2[:, None, :, None], t3[None, :, :, None],
             t4[:, None, None, :], t5[None, :, None, :], t6[None, None, :, :])
        if not self.aff:
            f = b[0] * b[1] * b[2] * b[3] * b[4] * b[5]
            return self.model.mapping(f)
        return aff_head(self.model, b)                           # (nh, nd, np, nl)


def aff_head(model: SpecGen, rows) -> torch.Tensor:
    """r' from the six AFF table rows ``[W1·f_k, m_k·f_k]`` (``(…, C+1)`` each, broadcastable):
    the statistic ``s = Σ_k m_k·f_k + b``, the branch weights, ``h1 = b1 + Σ_k w_k W1·f_k``, and
    layers 2–3 (the per-point remainder of :class:`GridHead`)."""
    mapping = model.mapping
    _, bias = model.fusion.gap_functionals()
    s = rows[0][..., -1] + rows[1][..., -1] + rows[2][..., -1] + rows[3][..., -1] + rows[4][..., -1] \
        + rows[5][..., -1] + bias
    w = model.fusion.weights_from_statistic(s)                   # (…, 6)
    h = mapping.fc1.bias + w[..., 0:1] * rows[0][..., :-1]
    for k in range(1, 6):
        h = h + w[..., k:k + 1] * rows[k][..., :-1]
    h = torch.relu(h)
    h = torch.relu(mapping.fc2(h))
    return mapping.fc3(h)[..., 0]


def head_at_nodes(model: SpecGen, tables, i: torch.Tensor, j: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """r' ``(U, Λ)`` at U grid nodes (θh index ``i``, θd index ``j``, φd index ``k``) and every band
    of the AFF tables: :class:`GridHead` for a list of nodes instead of a block (differentiable)."""
    t1, t2, t3, t4, t5, t6 = tables
    return aff_head(model, (t1[i, j][:, None], t2[i, k][:, None], t3[j, k][:, None],   # (U, 1, C+1)
                            t4[i], t5[j], t6[k]))                                      # (U, Λ, C+1)


class GridHeadChannelsFirst(GridHead):
    """:class:`GridHead` rearranged for onnxruntime: the same operations (same output to float
    rounding) in a channels-first layout ``(C, Λ, nh, nd, 180)``.

    In the table layout ``(…, C)`` every broadcast product ``w_k · f_k`` runs over spans of C = 32
    values, and onnxruntime's elementwise kernels pay their per-span overhead ~1 M times per block.
    With the channels outermost and φd innermost, every operand broadcasts over spans of ≥ 180
    contiguous values (or is a scalar per span), and the three linear layers become plain matrix
    products ``W (out, C) @ h (C, points)``.

    Inputs are the blocks of :func:`specgen_addon.model.runtime.inference.channels_first_tables` (arranged once per
    grid, not per block): the AFF statistic rows ``s1 … s6`` (Λ|1, nh|1, nd|1, 180|1) and the
    feature rows ``f1 … f6`` (C, Λ|1, nh|1, nd|1, 180|1). Output: r' (Λ, nh, nd, 180). AFF only.
    """

    def forward(self, s1, s2, s3, s4, s5, s6, f1, f2, f3, f4, f5, f6) -> torch.Tensor:
        fusion, mapping = self.model.fusion, self.model.mapping
        _, bias = fusion.gap_functionals()
        s = s1 + s2 + s3 + s4 + s5 + s6 + bias                                     # (Λ, nh, nd, φd)
        shape = s.shape
        s = s.reshape(1, -1)
        z = torch.relu(fusion.expand.weight @ s + fusion.expand.bias[:, None])      # (d, P)
        logits = fusion.heads.weight @ z + fusion.heads.bias[:, None]              # (6, P)
        # softmax over the six rows with elementwise ops (a reduction over the leading axis is
        # slow in onnxruntime)
        top = logits[0]
        for k in range(1, 6):
            top = torch.maximum(top, logits[k])
        e = torch.exp(logits - top)
        total = e[0] + e[1] + e[2] + e[3] + e[4] + e[5]
        w = (e / total).reshape((6, 1) + tuple(shape))                             # (6, 1, Λ, …)
        f = (f1, f2, f3, f4, f5, f6)
        h = mapping.fc1.bias[:, None, None, None, None] + w[0] * f[0]
        for k in range(1, 6):
            h = h + w[k] * f[k]
        h = torch.relu(h).reshape(h.shape[0], -1)
        h = torch.relu(mapping.fc2.weight @ h + mapping.fc2.bias[:, None])
        return (mapping.fc3.weight @ h + mapping.fc3.bias[:, None]).reshape(shape)  # (Λ, nh, nd, φd)


class GridHeadLowRank(GridHead):
    """:class:`GridHeadChannelsFirst` with three of the six weighted features summed by one matrix
    product per band, for onnxruntime: the same output to float rounding, ~25 % less time per block.

    Within a block (one θh row, θd rows ``j … j+nd``) the features ``f1 (θh, θd)``, ``f4 (θh, λ)``
    and ``f5 (θd, λ)`` take only ``2 nd + 1`` values per band, so their weighted sum with the
    first layer's bias, ``b1 + w1 f1 + w4 f4 + w5 f5``, is the product ``L_λ (C, 2nd + 2) @ M_λ
    (2nd + 2, nd·180)`` of those values with their AFF weights (each weight in the row of the value
    it multiplies, ``eye`` sorting ``w1`` and ``w5`` by θd row): one pass instead of eight
    elementwise ones. The three others, ``f2 (θh, φd)``, ``f3 (θd, φd)``, ``f6 (φd, λ)``, are
    multiplied and added as in the channels-first head, and layers 2–3 are 1×1 convolutions over
    the points of each band.

    Inputs (:func:`specgen_addon.model.runtime.inference.low_rank_block`): the AFF statistic rows ``s1 … s6``
    (Λ|1, 1, nd|1, 180|1) as :class:`GridHeadChannelsFirst`; ``low (Λ, C, 2nd + 1)`` =
    ``[f1 of the nd rows | f4 | f5 of the nd rows]``; ``f2 (1, C, 1, 180)``, ``f3 (1, C, nd, 180)``,
    ``f6 (Λ, C, 1, 180)``; ``eye (nd, nd)``. Output: r' (Λ, 1, nd, 180). AFF only.
    """

    def forward(self, s1, s2, s3, s4, s5, s6, low, f2, f3, f6, eye) -> torch.Tensor:
        fusion, mapping = self.model.fusion, self.model.mapping
        _, bias = fusion.gap_functionals()
        s = s1 + s2 + s3 + s4 + s5 + s6 + bias                                     # (Λ, 1, nd, φd)
        shape = s.shape
        n_l, nd, n_phi = shape[0], shape[2], shape[3]
        z = torch.relu(fusion.expand.weight @ s.reshape(1, -1) + fusion.expand.bias[:, None])
        logits = fusion.heads.weight @ z + fusion.heads.bias[:, None]              # (6, P)
        top = logits[0]                   # softmax with elementwise ops, as the channels-first head
        for k in range(1, 6):
            top = torch.maximum(top, logits[k])
        e = torch.exp(logits - top)
        w = (e / (e[0] + e[1] + e[2] + e[3] + e[4] + e[5])).reshape(6, n_l, nd, n_phi)
        q = nd * n_phi
        by_row = eye[None, :, :, None]                                            # θd row d → row d
        m = torch.cat([torch.ones_like(w[3]).reshape(n_l, 1, q),
                       (w[0][:, None] * by_row).reshape(n_l, nd, q),
                       w[3].reshape(n_l, 1, q),
                       (w[4][:, None] * by_row).reshape(n_l, nd, q)], 1)            # (Λ, 2nd + 2, Q)
        b1 = mapping.fc1.bias[None, :, None].expand(n_l, -1, 1)
        h = (torch.cat([b1, low], 2) @ m).reshape(n_l, -1, nd, n_phi)              # (Λ, C, nd, φd)
        h = h + w[1][:, None] * f2 + w[2][:, None] * f3 + w[5][:, None] * f6
        h = torch.relu(h).reshape(n_l, h.shape[1], q)
        h = torch.relu(F.conv1d(h, mapping.fc2.weight[:, :, None], mapping.fc2.bias))
        r = F.conv1d(h, mapping.fc3.weight[:, :, None], mapping.fc3.bias)           # (Λ, 1, Q)
        return r.reshape(n_l, 1, nd, n_phi)
