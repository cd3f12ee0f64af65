"""A second image encoder whose output is added to the first one's latent (``boost_channels``).

Studies (lab/notebook) found the trained decoder able to do far better than
the latent its encoder gives it (its best latents beat the encoder's by 4.6 dB in μ-law MSE on
the training materials), while the trained encoder stood still when trained further and a new
encoder of the same size flattened just above it. This branch adds capacity on the encoder's side
without disturbing what is trained: ``z = encoder(x) + boost(x)``, where the boost is a stack of
stride-2 3×3 convs with leaky ReLUs (slope :data:`NEGATIVE_SLOPE`, so no unit dies for good), a
bottleneck linear layer and a last linear layer to the latent that starts at zero. A model that
gains the branch therefore computes exactly what it computed before (:mod:`.grow`), and training
the branch alone (``frozen`` naming every other module) can only add to the trained network.
"""

from __future__ import annotations

import torch
from torch import nn

from specgen_addon.model.config import Config
from specgen_addon.model.encoder import ImageEncoder, pixel_coords

#: Slope below zero of every activation in the branch.
NEGATIVE_SLOPE = 0.01


class BoostEncoder(nn.Module):
    """Image ``(B, 3, S, S)`` linear RGB -> latent correction ``(B, latent_dim)``, zero at start.

    It sees what the main encoder sees: the log-compressed image at the conv stack's size
    (:meth:`.encoder.ImageEncoder.base_image`) with the two coordinate channels.
    """

    def __init__(self, cfg: Config):
        super().__init__()
        layers: list[nn.Module] = []
        c_in = 5
        for c in cfg.boost_channels:
            layers += [nn.Conv2d(c_in, c, 3, stride=2, padding=1), nn.LeakyReLU(NEGATIVE_SLOPE)]
            c_in = c
        self.convs = nn.Sequential(*layers)
        base = cfg.image_size // cfg.detail_factor
        side = base // 2 ** len(cfg.boost_channels)
        self.head = nn.Sequential(nn.Linear(c_in * side * side, cfg.boost_width), nn.LeakyReLU(NEGATIVE_SLOPE),
                                  nn.Linear(cfg.boost_width, cfg.latent_dim))
        nn.init.zeros_(self.head[-1].weight)
        nn.init.zeros_(self.head[-1].bias)
        self.register_buffer("coords", pixel_coords(base), persistent=False)

    def forward(self, image: torch.Tensor, encoder: ImageEncoder) -> torch.Tensor:
        x = encoder.compress(encoder.base_image(image))
        x = torch.cat([x, self.coords.expand(x.shape[0], -1, -1, -1)], dim=1)
        return self.head(self.convs(x).flatten(1))
