"""BRDF mapping module (paper §3.2, Eq. 12): three-layer ReLU MLP, fused feature -> r' (μ-law)."""

from __future__ import annotations

import torch
from torch import nn

from specgen_addon.model.config import Config


class BRDFMapping(nn.Module):
    """``r' = MLP(f_u; δ)``: Linear(C, h1) → ReLU → Linear(h1, h2) → ReLU → Linear(h2, 1).

    The output is the μ-law compressed reflectance r' (unbounded linear output: specular peaks
    with r > 1 sr⁻¹ give r' > 1).
    """

    def __init__(self, cfg: Config):
        super().__init__()
        h1, h2 = cfg.mlp_hidden
        self.fc1 = nn.Linear(cfg.feature_dim, h1)
        self.fc2 = nn.Linear(h1, h2)
        self.fc3 = nn.Linear(h2, 1)

    def forward(self, f_u: torch.Tensor) -> torch.Tensor:
        h = torch.relu(self.fc1(f_u))
        h = torch.relu(self.fc2(h))
        return self.fc3(h)[..., 0]
