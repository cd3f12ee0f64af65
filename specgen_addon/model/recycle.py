"""Recycle dormant ReLU units without changing what the network computes.

A ReLU unit that is off for every input gets no gradient, so training never brings it back
(:mod:`.activity` counts them; the shipped encoder uses 66 of its 256 latent units). Following
ReDo (Sokar et al. 2023, "The Dormant Neuron Phenomenon in Deep Reinforcement Learning"), each
dormant unit gets fresh incoming weights and its outgoing weights are set to zero: the network's
output is unchanged for every input on which the unit was off (every census input; a unit off
for a large, varied census is off almost everywhere), and the unit is alive again, so the next
training step can use it. Here the fresh unit's bias is set so that it is on for half of the census inputs (ReDo
redraws it at random, which can leave the unit dead again).

Stages: each encoder conv, the latent (the encoder's linear layer), each decoder trunk conv and
each plane head's hidden conv. The decoder's seed map is left alone: its units are single
positions of a map whose next layer is a convolution, so one of them cannot be silenced alone.
"""

from __future__ import annotations

import math
from typing import Callable, Iterator

import torch
import torch.nn.functional as F
from torch import nn

from specgen_addon.model.specgen import SpecGen

#: Stages :func:`recycle_dormant` can renew.
STAGES = ("encoder", "latent", "trunk", "heads")


def unsupported(cfg) -> str | None:
    """Why a network of config ``cfg`` cannot be recycled, or None if it can."""
    if cfg.detail_factor > 1 or cfg.latent_res_blocks or cfg.trunk_res_blocks or cfg.trunk_upsample_stages:
        return ("recycling supports networks without an encoder detail branch, latent or trunk blocks "
                "and finer trunk stages")
    if cfg.encoder_negative_slope:
        return "recycling supports ReLU encoders only (a leaky unit below zero is not silent)"
    return None


def _layers(model: SpecGen) -> list[tuple[str, str, nn.Module, list[tuple[nn.Module, int]]]]:
    """``(stage, name, layer, consumers)``: each ReLU-fed layer and the layers reading its units
    (a consumer ``(module, block)`` reads unit k through input columns ``k*block … (k+1)*block``)."""
    enc, gen = model.encoder, model.generator
    why = unsupported(model.cfg)
    if why:
        raise ValueError(why)
    out = []
    convs = [m for m in enc.convs if isinstance(m, nn.Conv2d)]
    side = (model.cfg.image_size // model.cfg.detail_factor) // 2 ** len(convs)
    for i, conv in enumerate(convs):
        nxt = [(convs[i + 1], 1)] if i + 1 < len(convs) else [(enc.fc, side * side)]
        out.append(("encoder", f"encoder conv {i + 1}", conv, nxt))
    readers = [(gen.seed, 1)] + ([(gen.spectral, 1)] if gen.spectral is not None else [])
    out.append(("latent", "latent", enc.fc, readers))
    tconvs = [m for m in gen.trunk if isinstance(m, nn.Conv2d)]
    for i, conv in enumerate(tconvs):
        nxt = [(tconvs[i + 1], 1)] if i + 1 < len(tconvs) else [(h[0], 1) for h in gen.heads.values()]
        out.append(("trunk", f"decoder trunk conv {i + 1}", conv, nxt))
    for name, head in gen.heads.items():
        out.append(("heads", f"plane head {name}", head[0], [(head[2], 1)]))
    return out


def _inputs_and_preactivations(forward: Callable[[], object], layer: nn.Module
                               ) -> tuple[torch.Tensor, torch.Tensor]:
    """The input of ``layer`` and its output (pre-activation) in the pass ``forward`` runs; the
    pass stops at ``layer`` (the census of a large training set runs it once per layer)."""
    seen: dict[str, torch.Tensor] = {}

    class Captured(Exception):
        pass

    def keep(_m, inp, out):
        seen["x"], seen["y"] = inp[0].detach(), out.detach()
        raise Captured

    handle = layer.register_forward_hook(keep)
    try:
        with torch.no_grad():
            forward()
    except Captured:
        pass
    finally:
        handle.remove()
    return seen["x"], seen["y"]


def _unit_on(y: torch.Tensor) -> torch.Tensor:
    """``(units,)``: a unit (a channel of a map) is on if positive anywhere for any input."""
    return (y > 0).transpose(0, 1).reshape(y.shape[1], -1).any(1)


def _dead_units(model: SpecGen, images: torch.Tensor, stages: tuple[str, ...]
                ) -> Iterator[tuple[str, nn.Module, list[tuple[nn.Module, int]], torch.Tensor, torch.Tensor]]:
    """``(name, layer, consumers, layer input, dead unit indices)`` for each layer of ``stages``,
    input to output, its census taken when it is reached, so it sees what the caller did to the
    layers before it. The encoder's stages come first; once they are done, the encoder's output
    (which the decoder's census reads) is computed once for every decoder layer."""
    unknown = set(stages) - set(STAGES)
    if unknown:
        raise ValueError(f"unknown stage {sorted(unknown)[0]!r}; choose from {', '.join(STAGES)}")
    decoder_input: tuple[torch.Tensor, torch.Tensor] | None = None
    for stage, name, layer, consumers in _layers(model):
        if stage not in stages:
            continue
        if stage in ("encoder", "latent"):
            x, y = _inputs_and_preactivations(lambda: model.encoder(images), layer)
        else:
            if decoder_input is None:
                decoder_input = (model.latent(images), model.encoder.colour(images))
            x, y = _inputs_and_preactivations(lambda: model.generator(*decoder_input), layer)
        yield name, layer, consumers, x, torch.nonzero(~_unit_on(y)).flatten()


@torch.no_grad()
def recycle_dormant(model: SpecGen, images: torch.Tensor, stages: tuple[str, ...] = STAGES,
                    seed: int = 0) -> dict[str, int]:
    """Renew the units of ``stages`` that are off for all ``images`` ``(B, 3, S, S)``; returns the
    number renewed per layer. The model's output is unchanged for every input on which the renewed
    units were off, the census ``images`` included."""
    gen = torch.Generator().manual_seed(seed)
    renewed: dict[str, int] = {}
    for name, layer, consumers, x, dead in _dead_units(model, images, stages):
        renewed[name] = int(dead.numel())
        if not dead.numel():
            continue
        w = layer.weight
        fan_in = w[0].numel()
        bound = 1.0 / math.sqrt(fan_in)          # PyTorch's default init: kaiming_uniform(a=√5)
        fresh = (torch.rand((dead.numel(), *w.shape[1:]), generator=gen) * 2.0 - 1.0) * bound
        w[dead] = fresh.to(w.dtype)
        if isinstance(layer, nn.Conv2d):
            pre = F.conv2d(x, fresh.to(x.dtype), None, layer.stride, layer.padding)
            pre = pre.transpose(0, 1).reshape(dead.numel(), -1)
        else:
            pre = (x @ fresh.to(x.dtype).T).T
        layer.bias[dead] = -pre.median(dim=1).values.to(layer.bias.dtype)   # on for half the inputs
        for reader, block in consumers:
            cols = (dead[:, None] * block + torch.arange(block)[None]).flatten()
            reader.weight[:, cols] = 0.0
    return renewed


@torch.no_grad()
def revive_at_boundary(model: SpecGen, images: torch.Tensor, stages: tuple[str, ...] = ("encoder", "latent"),
                       epsilon: float = 1e-4) -> dict[str, int]:
    """Put the units of ``stages`` that are off for all ``images`` just above their ReLU's kink:
    incoming weights zero, bias ``epsilon``; returns the number revived per layer.

    Unlike :func:`recycle_dormant` the units' outgoing weights are kept, so a consumer that does
    not train (a frozen decoder reading the latent) still reads them through its columns, which
    never trained either (a dead unit passes no gradient to them). The output moves by
    ``epsilon`` times those columns; each revived unit is on for every input and takes gradient.
    """
    if not epsilon > 0:
        raise ValueError(f"epsilon must be > 0, got {epsilon!r}")
    revived: dict[str, int] = {}
    for name, layer, _consumers, _x, dead in _dead_units(model, images, stages):
        revived[name] = int(dead.numel())
        layer.weight[dead] = 0.0
        layer.bias[dead] = epsilon
    return revived


__all__ = ["STAGES", "recycle_dormant", "revive_at_boundary", "unsupported"]
