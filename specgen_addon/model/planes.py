"""Spectral-spatial tri-planes (paper §3.1): generation from the latent, and bilinear projection.

Six planes, K-Planes style: spatial ``F_d1 (θh, θd)``, ``F_d2 (θh, φd)``, ``F_d3 (θd, φd)`` and
spectral ``F_e1 (θh, λ)``, ``F_e2 (θd, λ)``, ``F_e3 (φd, λ)``, each ``C × rows × cols``. They are
produced by a small convolutional decoder (not the release's giant MLPs). The projector ``P`` of
Eq. (3)–(4) is bilinear interpolation (``grid_sample``, ``align_corners=True``) at normalised
coordinates: θh is √-warped like MERL (``u = √(θh / (π/2))``), θd is linear over [0, π/2], φd is
folded into [0, π) and linear over [0, π], λ is linear over the configured range.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from specgen_addon.model.config import Config
from specgen_addon.model.residual import conv_blocks, upsample_stages

PLANE_NAMES = ("d1", "d2", "d3", "e1", "e2", "e3")
# Which coordinate indexes the rows and the columns of each plane.
PLANE_AXES = {"d1": ("theta_h", "theta_d"), "d2": ("theta_h", "phi_d"), "d3": ("theta_d", "phi_d"),
              "e1": ("theta_h", "lambda"), "e2": ("theta_d", "lambda"), "e3": ("phi_d", "lambda")}


def normalized_coords(theta_h: torch.Tensor, theta_d: torch.Tensor, phi_d: torch.Tensor,
                      wavelength_nm: torch.Tensor | None, cfg: Config) -> dict[str, torch.Tensor]:
    """Map Rusinkiewicz angles (radians) and wavelength (nm) to plane coordinates in [-1, 1]."""
    half_pi = math.pi / 2
    u = {"theta_h": 2.0 * torch.sqrt(theta_h.clamp(0.0, half_pi) / half_pi) - 1.0,
         "theta_d": 2.0 * theta_d.clamp(0.0, half_pi) / half_pi - 1.0,
         "phi_d": 2.0 * torch.remainder(phi_d, math.pi) / math.pi - 1.0}
    if wavelength_nm is not None:
        span = cfg.lambda_max_nm - cfg.lambda_min_nm
        u["lambda"] = (2.0 * (wavelength_nm - cfg.lambda_min_nm) / span - 1.0).clamp(-1.0, 1.0)
    return u


def sample_plane(plane: torch.Tensor, u_rows: torch.Tensor, u_cols: torch.Tensor) -> torch.Tensor:
    """Bilinear projection ``P``: plane ``(B, C, R, K)`` at coords ``(B, N)`` -> features ``(B, N, C)``."""
    grid = torch.stack([u_cols, u_rows], dim=-1)[:, None]  # (B, 1, N, 2): x = cols, y = rows
    out = F.grid_sample(plane, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return out[:, :, 0].transpose(1, 2)


def project(planes: dict[str, torch.Tensor], u: dict[str, torch.Tensor]) -> torch.Tensor:
    """Eq. (3)–(4): the six C-dim features at each point, ``(B, N, 6, C)`` in order d1..e3.

    Without a ``"lambda"`` coordinate (RGB samples, §3.3) the spectral features are averaged over
    the λ texels of each spectral plane: ``f̂_ei = 1/M Σ_λ P_Fei``.
    """
    feats = []
    for name in PLANE_NAMES:
        rows, cols = PLANE_AXES[name]
        plane = planes[name]
        if cols == "lambda" and "lambda" not in u:
            plane = plane.mean(dim=3, keepdim=True)
            feats.append(sample_plane(plane, u[rows], torch.zeros_like(u[rows])))
        else:
            feats.append(sample_plane(plane, u[rows], u[cols]))
    return torch.stack(feats, dim=2)


class PlaneGenerator(nn.Module):
    """Convolutional plane decoder: latent -> six planes ``(B, C, rows, cols)``.

    A linear layer makes a small seed map, upsampling 3×3 convs grow it into a shared trunk, and
    one light head per plane resamples the trunk to that plane's texel grid and emits C channels.
    A learned static plane is added to each (the material-independent part of BRDF structure),
    and with ``spectral_code`` a linear map of the latent and the image's mean colour
    (:meth:`ImageEncoder.colour`) adds a per-material λ profile
    ``(C, 1, res_lambda)`` to each spectral plane: convolutions are translation-equivariant, so
    without it the material's spectrum has to be placed along the λ axis by the seed map alone
    (a first model trained that way predicted nearly the same spectral shape for every material).
    With ``spectral_code_knots`` A > 1 the profile is given at A knots along the plane's angle axis
    ``(C, A, res_lambda)`` and interpolated linearly to its rows, so the highlight (small θh) can
    have another colour than the body, and a thin film's spectrum can change with θd.
    """

    def __init__(self, cfg: Config):
        super().__init__()
        self.cfg = cfg
        c0 = cfg.decoder_channels[0]
        h0, w0 = cfg.decoder_seed_hw
        self.seed = nn.Linear(cfg.latent_dim, c0 * h0 * w0)
        ups: list[nn.Module] = []
        for c_prev, c in zip(cfg.decoder_channels[:-1], cfg.decoder_channels[1:]):
            ups += [nn.Upsample(scale_factor=2, mode="nearest"), nn.Conv2d(c_prev, c, 3, padding=1),
                    nn.ReLU(inplace=True)]
        c_last = cfg.decoder_channels[-1]
        self.trunk = nn.Sequential(*ups, *conv_blocks(cfg.trunk_res_blocks, c_last))
        #: Finer trunk stages (``trunk_upsample_stages``): a sharp lobe or sheen rim a few plane
        #: texels wide needs more than the 16-row trunk the heads resample (lab/notebook/capacity.md).
        self.refine = upsample_stages(cfg.trunk_upsample_stages, c_last)
        self.heads = nn.ModuleDict({
            name: nn.Sequential(nn.Conv2d(c_last, cfg.head_channels, 3, padding=1), nn.ReLU(inplace=True),
                                nn.Conv2d(cfg.head_channels, cfg.feature_dim, 1))
            for name in PLANE_NAMES})
        self.spectral = None
        if cfg.spectral_code:
            self.spectral = nn.Linear(cfg.latent_dim + 3,
                                      3 * cfg.feature_dim * cfg.spectral_code_knots * cfg.res_lambda)
            nn.init.normal_(self.spectral.weight, std=0.002)
            nn.init.zeros_(self.spectral.bias)
        base_mean = 1.0 if cfg.fusion == "hadamard" else 0.0
        self.static = nn.ParameterDict({
            name: nn.Parameter(base_mean + 0.1 * torch.randn(1, cfg.feature_dim, *shape))
            for name, shape in cfg.plane_shapes.items()})

    def forward(self, latent: torch.Tensor, colour: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        return self.planes_from(*self.trunk_and_code(latent, colour))

    def trunk_and_code(self, latent: torch.Tensor, colour: torch.Tensor | None = None
                       ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The material-dependent inputs of the heads: the shared trunk map ``(B, c, h, w)`` and
        the spectral code ``(B, 3, C, knots, res_lambda)`` (``None`` without ``spectral_code``)."""
        c0 = self.cfg.decoder_channels[0]
        h0, w0 = self.cfg.decoder_seed_hw
        trunk = self.refine(self.trunk(torch.relu(self.seed(latent)).view(-1, c0, h0, w0)))
        if self.spectral is None:
            return trunk, None
        cfg = self.cfg
        if colour is None:
            colour = latent.new_zeros(latent.shape[0], 3)
        code = self.spectral(torch.cat([latent, colour], dim=1))
        return trunk, code.view(-1, 3, cfg.feature_dim, cfg.spectral_code_knots, cfg.res_lambda)

    def planes_from(self, trunk: torch.Tensor, code: torch.Tensor | None) -> dict[str, torch.Tensor]:
        """The six planes from the trunk map and the spectral code (see :meth:`trunk_and_code`)."""
        planes = {}
        for name, shape in self.cfg.plane_shapes.items():
            t = F.interpolate(trunk, size=shape, mode="bilinear", align_corners=True)
            planes[name] = self.static[name] + self.heads[name](t)
        if code is not None:
            for k, name in enumerate(("e1", "e2", "e3")):
                ck = code[:, k]
                if self.cfg.spectral_code_knots > 1:  # knots -> the plane's rows, linearly
                    ck = F.interpolate(ck, size=self.cfg.plane_shapes[name], mode="bilinear",
                                       align_corners=True)
                planes[name] = planes[name] + ck
        return planes


def tv_loss(planes: dict[str, torch.Tensor]) -> torch.Tensor:
    """Total-variation smoothness ``L_TV`` (§3.3): mean squared neighbour differences, all planes."""
    total = 0.0
    for p in planes.values():
        total = total + (p[:, :, 1:] - p[:, :, :-1]).pow(2).mean() + (p[..., 1:] - p[..., :-1]).pow(2).mean()
    return total / len(planes)
