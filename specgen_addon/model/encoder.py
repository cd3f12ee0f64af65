"""Image encoder: RGB sphere image -> latent vector (the encoder half of the paper's Fig. 2)."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from specgen_addon.photo.resample import aa_bilinear_weights
from specgen_addon.model.config import Config
from specgen_addon.model.residual import mlp_blocks


def pixel_coords(size: int) -> torch.Tensor:
    """``(1, 2, size, size)``: pixel x and y in [-1, 1] (image rows run down the sphere)."""
    ys, xs = torch.meshgrid(torch.linspace(-1, 1, size), torch.linspace(-1, 1, size), indexing="ij")
    return torch.stack([xs, ys])[None]


class ImageEncoder(nn.Module):
    """Stride-2 3×3 convolutions with ReLU, then a linear layer to ``latent_dim`` and a ReLU.

    With ``encoder_negative_slope`` s > 0 every one of those ReLUs is a leaky ReLU of slope s.

    Input ``(B, 3, S, S)`` linear RGB in roughly [0, 1] (S = ``image_size``); the image is
    log-compressed first (``log1p(16·x)/log(17)``) so specular highlights do not dominate.
    Two extra coordinate channels (x, y in [-1, 1]) tell the convolutions where on the sphere
    each pixel lies, i.e. which directions it saw. ``latent_res_blocks`` residual MLP blocks
    follow the linear layer.

    With ``detail_factor`` k > 1 the conv stack sees the image resampled to S/k (the antialiased
    bilinear weights of :func:`specgen_addon.photo.resample.resample_square`, as fixed matrices), and a
    *detail branch* of stride-2 convs sees it at full size, so a sharp highlight spans k² times
    as many pixels. The branch's output joins the first conv's before its ReLU; its last layer
    starts at zero, so weights of the S/k model start this one exactly (:mod:`.grow`).
    """

    def __init__(self, cfg: Config):
        super().__init__()
        layers: list[nn.Module] = []
        c_in = 5
        self.negative_slope = float(cfg.encoder_negative_slope)
        for c in cfg.encoder_channels:
            act = nn.LeakyReLU(self.negative_slope, inplace=True) if self.negative_slope else nn.ReLU(inplace=True)
            layers += [nn.Conv2d(c_in, c, 3, stride=2, padding=1), act]
            c_in = c
        self.convs = nn.Sequential(*layers)
        base = cfg.image_size // cfg.detail_factor
        side = base // 2 ** len(cfg.encoder_channels)
        self.fc = nn.Linear(c_in * side * side, cfg.latent_dim)
        self.res = mlp_blocks(cfg.latent_res_blocks, cfg.latent_dim)
        self.register_buffer("coords", pixel_coords(base), persistent=False)
        self.detail: nn.Sequential | None = None
        if cfg.detail_factor > 1:
            w = torch.from_numpy(aa_bilinear_weights(cfg.image_size, base)).float()
            self.register_buffer("down", w, persistent=False)          # (base, S): rows and columns alike
            self.register_buffer("coords_full", pixel_coords(cfg.image_size), persistent=False)
            width = max(8, cfg.encoder_channels[0] // 2)
            stages: list[nn.Module] = []
            c = 5
            for _ in range(int(math.log2(cfg.detail_factor))):       # S → S/k
                stages += [nn.Conv2d(c, width, 3, stride=2, padding=1), nn.ReLU()]
                c = width
            last = nn.Conv2d(c, cfg.encoder_channels[0], 3, stride=2, padding=1)  # S/k → S/2k, as convs[0]
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)
            self.detail = nn.Sequential(*stages, last)

    @staticmethod
    def compress(image: torch.Tensor) -> torch.Tensor:
        return torch.log1p(16.0 * image.clamp_min(0.0)) / math.log(17.0)

    def base_image(self, image: torch.Tensor) -> torch.Tensor:
        """The linear image at the conv stack's size (itself unless ``detail_factor`` > 1)."""
        if self.detail is None:
            return image
        return self.down @ image @ self.down.T

    def colour(self, image: torch.Tensor) -> torch.Tensor:
        """Mean log-compressed RGB over the frame ``(B, 3)``: the sphere's overall colour."""
        return self.compress(self.base_image(image)).mean(dim=(2, 3))

    def activate(self, pre: torch.Tensor) -> torch.Tensor:
        """The encoder's activation: ReLU, or a leaky ReLU with ``encoder_negative_slope`` > 0."""
        return F.leaky_relu(pre, self.negative_slope) if self.negative_slope else torch.relu(pre)

    def pre_activation(self, image: torch.Tensor) -> torch.Tensor:
        """The latent before its final activation ``(B, latent_dim)`` (with a ReLU, a unit negative
        here for every input is dead)."""
        x = self.compress(self.base_image(image))
        x = torch.cat([x, self.coords.expand(x.shape[0], -1, -1, -1)], dim=1)
        if self.detail is None:
            h = self.convs(x)
        else:
            full = torch.cat([self.compress(image), self.coords_full.expand(x.shape[0], -1, -1, -1)], dim=1)
            h = self.convs[1:](self.convs[0](x) + self.detail(full))
        return self.fc(h.flatten(1))

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.res(self.activate(self.pre_activation(image)))
