"""Image encoder: RGB sphere image -> latent vector (the encoder half of the paper's Fig. 2)."""

from __future__ import annotations

import math

import torch
from torch import nn

from .config import Config
from .residual import mlp_blocks


class ImageEncoder(nn.Module):
    """Stride-2 3×3 convolutions with ReLU, then a linear layer to ``latent_dim``.

    Input ``(B, 3, S, S)`` linear RGB in roughly [0, 1] (S = ``image_size``); the image is
    log-compressed first (``log1p(16·x)/log(17)``) so specular highlights do not dominate.
    Two extra coordinate channels (x, y in [-1, 1]) tell the convolutions where on the sphere
    each pixel lies, i.e. which directions it saw. ``latent_res_blocks`` residual MLP blocks
    follow the linear layer.
    """

    def __init__(self, cfg: Config):
        super().__init__()
        layers: list[nn.Module] = []
        c_in = 5
        for c in cfg.encoder_channels:
            layers += [nn.Conv2d(c_in, c, 3, stride=2, padding=1), nn.ReLU(inplace=True)]
            c_in = c
        self.convs = nn.Sequential(*layers)
        side = cfg.image_size // 2 ** len(cfg.encoder_channels)
        self.fc = nn.Linear(c_in * side * side, cfg.latent_dim)
        self.res = mlp_blocks(cfg.latent_res_blocks, cfg.latent_dim)
        ys, xs = torch.meshgrid(torch.linspace(-1, 1, cfg.image_size),
                                torch.linspace(-1, 1, cfg.image_size), indexing="ij")
        self.register_buffer("coords", torch.stack([xs, ys])[None], persistent=False)

    @staticmethod
    def compress(image: torch.Tensor) -> torch.Tensor:
        return torch.log1p(16.0 * image.clamp_min(0.0)) / math.log(17.0)

    @classmethod
    def colour(cls, image: torch.Tensor) -> torch.Tensor:
        """Mean log-compressed RGB over the frame ``(B, 3)``: the sphere's overall colour."""
        return cls.compress(image).mean(dim=(2, 3))

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        x = self.compress(image)
        x = torch.cat([x, self.coords.expand(x.shape[0], -1, -1, -1)], dim=1)
        return self.res(torch.relu(self.fc(self.convs(x).flatten(1))))
