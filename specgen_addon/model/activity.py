"""Which ReLU units of a SpecGen network ever switch on: a census of dead units.

A unit whose pre-activation is negative for every input passes no gradient through its ReLU,
so training can never bring it back: the network then has fewer units than its config says.
:func:`unit_census` counts, per ReLU stage, the units (channels, for convolutions) that are
positive somewhere for at least one of the given images, and how many are on per image.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from specgen_addon.model.specgen import SpecGen


@dataclass(frozen=True)
class StageActivity:
    """One ReLU stage: ``units`` in all, ``ever_active`` for some image, ``mean_active`` per image."""

    stage: str
    units: int
    ever_active: int
    mean_active: float


def _channels_on(a: torch.Tensor) -> torch.Tensor:
    """``(B, units)`` booleans: a unit (a channel, for a map) is on where it is positive anywhere."""
    return (a > 0).flatten(2).any(-1) if a.dim() > 2 else a > 0


def unit_census(model: SpecGen, images: torch.Tensor) -> list[StageActivity]:
    """The ReLU stages of ``model`` for ``images`` ``(B, 3, S, S)``, input to output.

    Stages: each encoder conv, the latent (the encoder's final ReLU), the decoder's seed map, each
    trunk conv and each plane head's hidden conv (channels summed over the six heads).
    """
    records: list[tuple[str, torch.Tensor]] = []

    def hook(name: str):
        def keep(_module: nn.Module, _inp, out: torch.Tensor) -> None:
            records.append((name, _channels_on(out.detach())))
        return keep

    relus = [(f"encoder conv {i // 2 + 1}", m) for i, m in enumerate(model.encoder.convs)
             if isinstance(m, (nn.ReLU, nn.LeakyReLU))]
    relus += [(f"decoder trunk conv {k + 1}", m) for k, m in
              enumerate(m for m in model.generator.trunk if isinstance(m, nn.ReLU))]
    relus += [(f"plane head {name}", head[1]) for name, head in model.generator.heads.items()]
    handles = [m.register_forward_hook(hook(name)) for name, m in relus]
    try:
        with torch.no_grad():
            enc = model.encoder
            pre = enc.pre_activation(images)
            records.append(("latent (encoder output)", pre > 0))
            latent = model.boosted(enc.res(enc.activate(pre)), images)  # the encoder's hooks fire once
            records.append(("decoder seed map", torch.relu(model.generator.seed(latent)) > 0))
            model.generator(latent, enc.colour(images))
    finally:
        for handle in handles:
            handle.remove()
    merged: dict[str, torch.Tensor] = {}          # in forward order: the hooks fire as they run
    for name, on in records:
        key = "plane heads (all six)" if name.startswith("plane head") else name
        merged[key] = on if key not in merged else torch.cat([merged[key], on], dim=1)
    return [StageActivity(k, int(on.shape[1]), int(on.any(0).sum()), float(on.sum(1).float().mean()))
            for k, on in merged.items()]


__all__ = ["StageActivity", "unit_census"]
