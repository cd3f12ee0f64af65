"""The SpecGen network (paper §3): image -> tri-planes -> projection -> fusion -> MLP -> r'.

Also the weights file format (``.pt``: config + state dict + provenance) and its loader, which
turns every way a file can be wrong into :class:`~specgen_addon.common.errors.WeightsError`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from torch import nn

from specgen_addon.common.errors import WeightsError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.model import checksums
from specgen_addon.model.config import Config
from specgen_addon.model.decoder import BRDFMapping
from specgen_addon.model.encoder import ImageEncoder
from specgen_addon.model.fusion import make_fusion
from specgen_addon.model.planes import PlaneGenerator, normalized_coords, project, tv_loss

WEIGHTS_FORMAT = "specgen-weights"
WEIGHTS_VERSION = 1
from specgen_addon.model.shipped import DEFAULT_WEIGHTS  # noqa: E402  (one definition, torch-free)


class SpecGen(nn.Module):
    """Image-conditioned spectral BRDF ``r' = f(θh, θd, φd, λ)`` in μ-law space."""

    def __init__(self, cfg: Config):
        super().__init__()
        self.cfg = cfg
        self.encoder = ImageEncoder(cfg)
        self.generator = PlaneGenerator(cfg)
        self.fusion = make_fusion(cfg)
        self.mapping = BRDFMapping(cfg)

    def latent(self, image: torch.Tensor) -> torch.Tensor:
        """The latent ``(B, latent_dim)`` the decoder reads."""
        return self.encoder(image)

    def planes(self, image: torch.Tensor) -> dict[str, torch.Tensor]:
        """The six planes ``{d1..e3: (B, C, rows, cols)}`` for images ``(B, 3, S, S)``."""
        return self.generator(self.latent(image), self.encoder.colour(image))

    def query(self, planes: dict[str, torch.Tensor], theta_h: torch.Tensor, theta_d: torch.Tensor,
              phi_d: torch.Tensor, wavelength_nm: torch.Tensor | None = None) -> torch.Tensor:
        """μ-law reflectance r' ``(B, N)`` at angles (radians) and wavelengths (nm), each ``(B, N)``.

        ``wavelength_nm=None`` evaluates the grey RGB response of §3.3 (λ-averaged spectral features).
        """
        u = normalized_coords(theta_h, theta_d, phi_d, wavelength_nm, self.cfg)
        return self.mapping(self.fusion(project(planes, u)))

    def forward(self, image: torch.Tensor, theta_h: torch.Tensor, theta_d: torch.Tensor,
                phi_d: torch.Tensor, wavelength_nm: torch.Tensor | None = None) -> torch.Tensor:
        return self.query(self.planes(image), theta_h, theta_d, phi_d, wavelength_nm)

    @staticmethod
    def tv_loss(planes: dict[str, torch.Tensor]) -> torch.Tensor:
        return tv_loss(planes)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def save_weights(model: SpecGen, path: str | Path, meta: dict[str, Any] | None = None,
                 overwrite: bool = True, half: bool = False) -> Path:
    """Write the weights file atomically: ``{format, version, config, state_dict, meta}``.

    ``half`` stores the tensors as float16 (half the size; loaded back as float32).
    """
    state = {k: v.detach().to("cpu", copy=True) for k, v in model.state_dict().items()}  # a GPU run too
    if half:
        state = {k: (v.half() if v.is_floating_point() else v) for k, v in state.items()}
    payload = {"format": WEIGHTS_FORMAT, "version": WEIGHTS_VERSION, "config": model.cfg.to_dict(),
               "state_dict": state, "meta": dict(meta or {})}
    with atomic_write(path, overwrite=overwrite) as tmp:
        torch.save(payload, tmp)
    checksums.record(path)  # a folder with SHA256SUMS (the shipped one) keeps its sums current
    return Path(path)


def load_weights(path: str | Path | None = None, expect: Config | None = None) -> SpecGen:
    """Load a SpecGen model in eval mode from ``path`` (default: the shipped weights).

    Raises :class:`WeightsError` when the file is missing, unreadable, not a SpecGen weights file,
    of another version, or when its tensors do not fit its config (or ``expect``).
    """
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    if path.is_dir():
        raise WeightsError(f"{path}: is a folder, expected a weights file (.pt)")
    if not path.is_file():
        raise WeightsError(f"{path}: weights file not found")
    if not os.access(path, os.R_OK):
        raise WeightsError(f"{path}: weights file is not readable (permission denied)")
    checksums.verify(path)  # a shipped file with flipped bytes would load and change the output
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt pickles/zips
        raise WeightsError(f"{path}: not a readable weights file ({type(exc).__name__})") from None
    if not isinstance(payload, dict) or payload.get("format") != WEIGHTS_FORMAT:
        raise WeightsError(f"{path}: not a SpecGen weights file")
    if payload.get("version") != WEIGHTS_VERSION:
        raise WeightsError(f"{path}: unsupported weights version {payload.get('version')!r}")
    try:
        # files written before the per-material spectral code existed did not have one, and
        # files written before its angle knots had one knot
        cfg = Config.from_dict({"spectral_code": False, "spectral_code_knots": 1, **payload["config"]})
    except Exception as exc:
        raise WeightsError(f"{path}: bad model config in weights ({exc})") from None
    if expect is not None and cfg != expect:
        raise WeightsError(f"{path}: weights were trained for a different model configuration")
    model = SpecGen(cfg)
    try:
        model.load_state_dict(payload["state_dict"], strict=True)
    except (RuntimeError, KeyError, TypeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise WeightsError(f"{path}: weights do not match their configuration ({first})") from None
    bad = sum(int((~torch.isfinite(t)).sum()) for t in payload["state_dict"].values()
              if torch.is_tensor(t) and t.is_floating_point())
    if bad:
        raise WeightsError(f"{path}: {bad:,} NaN or infinite values in the weights")
    model.meta = payload.get("meta", {})
    return model.eval()
