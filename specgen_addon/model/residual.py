"""Residual blocks that start as the identity, so a trained model can grow without changing.

A block computes ``x + body(x)`` where the body's last layer starts at zero: a model that gains
blocks computes exactly what it computed before, and training then uses the new capacity
(:mod:`.grow` warm-starts such models from smaller ones).
"""

from __future__ import annotations

import torch
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
