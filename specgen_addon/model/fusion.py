"""Feature fusion (paper §3.2): Adaptive Feature Fusion (AFF) and the K-Planes Hadamard product.

AFF, SKNet-like, following the paper's equations:

* reshape each of the six C-vectors to a ``1 × H × W`` map and apply a branch-specific 3×3 conv,
  sum the six results: ``f_h = Σ_i Conv(f_ei) + Σ_i Conv(f_di)``          (Eq. 6)
* ``s = GAP(f_h)``                                                          (Eq. 7)
* ``z = ReLU(Conv1×1(s))`` with ``z ∈ R^d``, d = 32                         (Eq. 8)
* ``z_i = Conv(z, β_i)`` for the six branches                               (Eq. 9)
* ``w = Softmax(z_1..z_6)``                                                 (Eq. 10)
* ``f_u = Σ_i w_i f_di + w_{i+3} f_ei``                                      (Eq. 11)

Hadamard fusion (the ablation) is the element-wise product of the six features.
"""

from __future__ import annotations

import torch
from torch import nn

from specgen_addon.model.config import Config


class AFF(nn.Module):
    """Adaptive Feature Fusion of six C-dim features ``(..., 6, C)`` -> ``(..., C)``."""

    def __init__(self, cfg: Config):
        super().__init__()
        self.map_hw = tuple(cfg.aff_map_hw)
        # One 1->1 channel 3×3 conv per branch, run as a grouped conv over the six branches.
        self.branch_convs = nn.Conv2d(6, 6, kernel_size=3, padding=1, groups=6)
        self.expand = nn.Linear(1, cfg.aff_d)   # 1×1 conv on the 1-channel statistic s
        self.heads = nn.Linear(cfg.aff_d, 6)    # six 1×1 convs β_i: R^d -> R

    def conv_matrices(self) -> torch.Tensor:
        """The branch convs as matrices ``(6, C, C)``: ``Conv_k(f)`` flattened ``= M_k @ f``.

        A 3×3 conv (zero padding) on the ``H × W`` view of a C-vector is a linear map of it; its
        matrix is the conv applied to the C basis vectors.
        """
        c = self.map_hw[0] * self.map_hw[1]
        w = self.branch_convs.weight
        eye = torch.eye(c, dtype=w.dtype, device=w.device).reshape(c, 1, *self.map_hw)
        cols = nn.functional.conv2d(eye.expand(c, 6, *self.map_hw), self.branch_convs.weight,
                                    bias=None, padding=1, groups=6)      # (C_in, 6, H, W)
        return cols.reshape(c, 6, c).permute(1, 2, 0)                      # (6, C_out, C_in)

    def hybrid_map(self, feats: torch.Tensor) -> torch.Tensor:
        """Eq. (6) literally: ``f_h = Σ_k Conv_k(reshape(f_k))``, shape ``(..., H, W)``."""
        lead = feats.shape[:-2]
        maps = feats.reshape(-1, 6, *self.map_hw)
        return self.branch_convs(maps).sum(dim=1).reshape(*lead, *self.map_hw)

    def gap_functionals(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``(m, b)`` with ``GAP(f_h) = Σ_k m_k · f_k + b``: Eq. (6)–(7) are linear in the features.

        ``m_k[q] = 1/(HW) Σ_t β_k[t] [q − t inside the map]``: the transposed conv of a constant map.
        """
        h, w = self.map_hw
        ones = torch.full((1, 6, h, w), 1.0 / (h * w), dtype=self.branch_convs.weight.dtype,
                          device=self.branch_convs.weight.device)
        m = nn.functional.conv_transpose2d(ones, self.branch_convs.weight, padding=1, groups=6)
        return m.reshape(6, h * w), self.branch_convs.bias.sum()

    def weights_from_statistic(self, s: torch.Tensor) -> torch.Tensor:
        """Eq. (8)–(10): statistic ``s`` (...) -> softmax branch weights ``w`` (..., 6)."""
        z = torch.relu(self.expand(s[..., None]))
        return torch.softmax(self.heads(z), dim=-1)

    def branch_weights(self, feats: torch.Tensor) -> torch.Tensor:
        """Softmax branch weights ``w`` (..., 6) of Eq. (6)–(10) for features ``(..., 6, C)``."""
        m, b = self.gap_functionals()
        s = torch.einsum("...kc,kc->...", feats, m) + b                   # = GAP(hybrid_map)
        return self.weights_from_statistic(s)

    def forward(self, feats: torch.Tensor) -> torch.Tensor:
        w = self.branch_weights(feats)
        return (w[..., None] * feats).sum(dim=-2)                          # Eq. (11)


class Hadamard(nn.Module):
    """K-Planes fusion: element-wise product of the six features."""

    def __init__(self, cfg: Config):
        super().__init__()

    def forward(self, feats: torch.Tensor) -> torch.Tensor:
        return feats.prod(dim=-2)


def make_fusion(cfg: Config) -> nn.Module:
    """The fusion module selected by ``cfg.fusion`` (``"aff"`` or ``"hadamard"``)."""
    return AFF(cfg) if cfg.fusion == "aff" else Hadamard(cfg)
