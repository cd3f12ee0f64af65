"""The training losses: the paper's μ-law MSE (§3.3) and the terms beside it.

All arrays are torch tensors ``(B, N)`` of r′ = ln(1 + μ·f_r) / ln(1 + μ) values over sampled
Rusinkiewicz angles (radians), with a ``valid`` mask of the same shape.
"""

from __future__ import annotations

import math

import torch


def masked_mse(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """The MSE of ``pred`` against ``target`` over the entries where ``valid`` is 1."""
    return ((pred - target) ** 2 * valid).sum() / valid.sum().clamp_min(1.0)


def balanced_mse(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor,
                 floor: float) -> torch.Tensor:
    """The masked MSE of ``(B, N)`` arrays in value, with the gradient of
    M̄ · mean_m log(MSE_m + floor·M̄) over the rows (materials), M̄ the batch's mean MSE held constant.

    The quality figure is a mean over materials of PSNR = −10·log10(MSE_m) (up to each material's
    normalisation), so a material's error counts relative to its own level: halving a well-fitted
    material's error gains as many dB as halving a poor one's. The gradient weighs each material's
    MSE by M̄ / (MSE_m + floor·M̄): the plain MSE's scale (and learning rate) is kept while the step
    steers as the figure does, and the floor keeps a nearly perfect material from taking the whole
    step. The value stays the plain MSE, so logged losses compare with the paper loss's.
    """
    squared = (pred - target) ** 2 * valid
    per = squared.sum(dim=1) / valid.sum(dim=1).clamp_min(1.0)
    level = per.mean().detach().clamp_min(1e-12)
    weights = (level / (per + floor * level)).detach()
    steer = (weights * per).mean()
    pooled = squared.sum() / valid.sum().clamp_min(1.0)   # the value masked_mse gives
    return pooled.detach() + steer - steer.detach()


def inverse_mu_law(r: torch.Tensor, mu: float) -> torch.Tensor:
    """f_r (sr⁻¹) from r′ = ln(1 + μ·f_r) / ln(1 + μ), the inverse of the paper's μ-law."""
    return torch.expm1(r * math.log1p(mu)) / mu


def foreshortening(theta_h: torch.Tensor, theta_d: torch.Tensor, phi_d: torch.Tensor) -> torch.Tensor:
    """min(cos θi, cos θo) of Rusinkiewicz angles (radians), clamped at 0.

    cos θi,o = cos θh·cos θd ∓ sin θh·sin θd·cos φd; the smaller of the two is symmetric in
    i ↔ o, so the weight needs no convention for which direction is the light.
    """
    c = (torch.cos(theta_h) * torch.cos(theta_d)
         - torch.sin(theta_h) * torch.sin(theta_d) * torch.cos(phi_d).abs())
    return c.clamp_min(0.0)


def rendered_scale_loss(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor,
                        cos_weight: torch.Tensor, mu: float) -> torch.Tensor:
    """Linear-space error of the radiance a BRDF sends toward a distant light's viewer, relative to
    each material's brightest sampled point: mean of ((f̂ − f)·cos / max(f·cos))² per row.

    The μ-law MSE weighs a relative error alike at every level; a rendered image's PSNR (normalised
    by its bright end) weighs the absolute error of the highlight and the body's overall scale.
    This term puts that weight into training. Arrays are ``(B, N)``; ``pred``/``target`` are r′.
    """
    f_true = inverse_mu_law(target, mu) * cos_weight
    f_pred = inverse_mu_law(pred.clamp(max=3.0), mu) * cos_weight   # r′ ≤ 3: f ≤ 6.6·10⁴ sr⁻¹
    scale = (f_true * valid).amax(dim=1, keepdim=True).clamp_min(1e-4).detach()
    return masked_mse(f_pred / scale, f_true / scale, valid)
