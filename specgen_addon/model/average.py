"""Weight averaging across one run's checkpoints (stochastic weight averaging, Izmailov et al. 2018).

A small batch leaves the weights jittering around the minimum the learning rate allows; the mean
of weights saved along the last stretch of a run sits closer to it. Training can keep such an
average as it goes (``ema_decay``, :mod:`specgen_addon.train.loop`); this module averages saved
files after the fact: weights files (``specgen.pt``) or training checkpoints (``checkpoint.pt``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import torch

from specgen_addon.common.errors import WeightsError
from specgen_addon.model.config import Config
from specgen_addon.model.specgen import SpecGen, load_weights


def load_any(path: str | Path) -> SpecGen:
    """A model from a weights file or from a training checkpoint (its raw, non-averaged weights)."""
    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt files
        raise WeightsError(f"{path}: not a readable weights file or checkpoint ({type(exc).__name__})") from None
    if isinstance(payload, dict) and {"model", "model_config", "step"} <= set(payload):
        model = SpecGen(Config.from_dict(payload["model_config"]))
        try:
            model.load_state_dict(payload["model"])
        except RuntimeError:
            raise WeightsError(f"{path}: checkpoint tensors do not fit its model config") from None
        model.meta = {"steps": int(payload["step"]), "train_config": payload.get("train_config", {})}
        return model.eval()
    return load_weights(path)


def average_models(paths: Sequence[str | Path]) -> SpecGen:
    """The element-wise mean of the weights in ``paths`` (all of one model configuration).

    Its ``meta`` is the latest source's (the one with the most training steps), plus
    ``averaged_from`` (the files) and ``averaged_steps`` (each source's step count).
    """
    if len(paths) < 2:
        raise WeightsError("averaging needs at least two weights files or checkpoints")
    models = [load_any(p) for p in paths]
    cfg = models[0].cfg
    for p, m in zip(paths[1:], models[1:]):
        if m.cfg != cfg:
            raise WeightsError(f"{p}: made for another model configuration than {paths[0]}")
    states = [m.state_dict() for m in models]
    mean = {k: (torch.stack([s[k].float() for s in states]).mean(0) if v.is_floating_point() else v)
            for k, v in states[0].items()}
    out = SpecGen(cfg)
    out.load_state_dict(mean)
    steps = [int(m.meta.get("steps", 0)) for m in models]  # load_any gives every model its meta
    latest = models[max(range(len(models)), key=steps.__getitem__)]
    out.meta = {**latest.meta, "averaged_from": [str(p) for p in paths], "averaged_steps": steps}
    return out.eval()
