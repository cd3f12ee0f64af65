"""Residual blocks that start as the identity, so a trained model can grow without changing.

A block computes ``x + body(x)`` where the body's last layer starts at zero: a model that gains
blocks computes exactly what it computed before, and training then uses the new capacity
(:mod:`.grow` warm-starts such models from smaller ones).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class ZeroResidual(nn.Module):
    """``x + body(x)``; the body's last layer starts with zero weights and bias."""

    def __init__(self, body: nn.Sequential):
        super().__init__()
        self.body = body
        last = body[-1]
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


def mlp_blocks(n: int, width: int) -> nn.Sequential:
    """``n`` residual Linear–ReLU–Linear blocks of ``width`` (identity at initialisation)."""
    return nn.Sequential(*(ZeroResidual(nn.Sequential(nn.Linear(width, width), nn.ReLU(),
                                                      nn.Linear(width, width))) for _ in range(n)))


def conv_blocks(n: int, channels: int) -> nn.Sequential:
    """``n`` residual 3×3 conv–ReLU–3×3 conv blocks (identity at initialisation)."""
    return nn.Sequential(*(ZeroResidual(nn.Sequential(nn.Conv2d(channels, channels, 3, padding=1), nn.ReLU(),
                                                      nn.Conv2d(channels, channels, 3, padding=1)))
                           for _ in range(n)))


class RefiningUpsample(nn.Module):
    """A map ``(B, c, h, w)`` → ``(B, c, 2h − 1, 2w − 1)``: bilinear midpoint insertion
    (``align_corners=True``), then a residual 3×3 conv–ReLU–1×1 conv block (identity at start).

    Inserting midpoints keeps the bilinear interpolant unchanged: any later bilinear resampling
    (``align_corners=True``) of the finer map equals that of the coarser one, so a trained model
    that gains this stage computes exactly what it computed before, and the block then learns
    detail at twice the resolution.
    """

    def __init__(self, channels: int):
        super().__init__()
        self.block = ZeroResidual(nn.Sequential(nn.Conv2d(channels, channels, 3, padding=1), nn.ReLU(),
                                                nn.Conv2d(channels, channels, 1)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        return self.block(F.interpolate(x, size=(2 * h - 1, 2 * w - 1), mode="bilinear", align_corners=True))


def upsample_stages(n: int, channels: int) -> nn.Sequential:
    """``n`` :class:`RefiningUpsample` stages (each keeps the function at initialisation)."""
    return nn.Sequential(*(RefiningUpsample(channels) for _ in range(n)))
