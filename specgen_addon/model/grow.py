"""Warm starts across a model change: carry trained weights into a larger configuration.

A training run may start from weights made for a smaller :class:`~.config.Config` when the two
differ only in the fields of :data:`GROWABLE`:

* ``spectral_code_knots`` (the per-material spectral code's knots along each spectral plane's
  angle axis): the code's linear map is resampled along its knot axis; from one knot this is
  exact (every knot starts as the old angle-constant profile) and training then moves the knots
  apart;
* ``latent_res_blocks`` and ``trunk_res_blocks`` (more, never fewer): the added residual blocks
  keep the new model's initial weights, which make them the identity (:mod:`.residual`);
* ``trunk_upsample_stages`` (more, never fewer): each added stage inserts midpoints into the
  trunk map bilinearly, which leaves every later bilinear resampling unchanged, and its residual
  block starts at zero (:class:`.residual.RefiningUpsample`);
* ``image_size`` with ``detail_factor`` (from no detail branch to a factor k, the image k times
  larger): the conv stack keeps its size, sees the larger image resampled by the same
  antialiased weights the input pipeline used, and the new detail branch starts at zero
  (:class:`.encoder.ImageEncoder`);

In each case the grown network computes the same function as the old one (to float rounding of
the resampling). Two changes are allowed that do not keep the function:

* ``encoder_negative_slope`` (:data:`RELAXED`): the same encoder weights under leaky ReLUs; a
  unit below zero now passes slope × its value, close to the old output for a small slope, and
  a dead unit takes gradient again;
* with ``fresh_encoder``, every field of the encoder alone (:data:`ENCODER_FIELDS`): the encoder
  keeps the new model's random initialisation and only the decoder, fusion and mapping are
  carried over (a new encoder trained for a trained decoder).
"""

from __future__ import annotations

import dataclasses

import torch
import torch.nn.functional as F

from specgen_addon.common.errors import SpecGenError
from specgen_addon.model.config import Config

#: Config fields a warm start may change.
GROWABLE = ("spectral_code_knots", "latent_res_blocks", "trunk_res_blocks", "trunk_upsample_stages",
            "image_size", "detail_factor")
#: Config fields a warm start may change although the function then changes (see above).
RELAXED = ("encoder_negative_slope",)
#: Config fields that only the encoder reads (``latent_dim`` is the decoder's input too).
ENCODER_FIELDS = ("image_size", "encoder_channels", "encoder_negative_slope", "detail_factor",
                  "latent_res_blocks")
#: Of the growable fields, the counts of identity-initialised blocks, which may only grow.
ADDED_BLOCKS = ("latent_res_blocks", "trunk_res_blocks", "trunk_upsample_stages")


def can_grow(old: Config, new: Config, fresh_encoder: bool = False) -> bool:
    """Whether weights of ``old`` can start a run of ``new`` (equal, or differing only in GROWABLE
    and RELAXED; with ``fresh_encoder`` also in ENCODER_FIELDS)."""
    a, b = dataclasses.asdict(old), dataclasses.asdict(new)
    free = GROWABLE + RELAXED + (ENCODER_FIELDS if fresh_encoder else ())
    if not all(a[k] == b[k] for k in a if k not in free) or old.spectral_code != new.spectral_code:
        return False
    if fresh_encoder:
        return all(b[k] >= a[k] for k in ADDED_BLOCKS if k not in ENCODER_FIELDS)
    same_stack = old.image_size // old.detail_factor == new.image_size // new.detail_factor
    branch_ok = old.detail_factor in (1, new.detail_factor)
    return all(b[k] >= a[k] for k in ADDED_BLOCKS) and same_stack and branch_ok


def grow_state_dict(state: dict[str, torch.Tensor], old: Config, new: Config,
                    fresh: dict[str, torch.Tensor] | None = None,
                    fresh_encoder: bool = False) -> dict[str, torch.Tensor]:
    """``state`` (a state dict of a ``old`` model) as a state dict for a ``new`` model.

    ``fresh`` is a newly built ``new`` model's state dict; the added residual blocks take their
    (identity) weights from it, so it is needed whenever ``new`` has more blocks than ``old``,
    and with ``fresh_encoder`` the whole encoder does.
    """
    if fresh_encoder:
        if not can_grow(old, new, fresh_encoder=True):
            raise SpecGenError("cannot carry the decoder over: the two configurations differ outside the "
                               "encoder and the growable fields")
        if fresh is None:
            raise SpecGenError("a fresh encoder needs the new model's initial weights (fresh)")
        decoder = {k: v for k, v in state.items() if not k.startswith("encoder.")}
        old_dec = dataclasses.replace(old, **{k: getattr(new, k) for k in ENCODER_FIELDS})
        out = grow_state_dict(decoder, old_dec, new, fresh=fresh)
        out.update({k: v.float().clone() for k, v in fresh.items() if k.startswith("encoder.")})
        return out
    if not can_grow(old, new):
        changed = sorted(k for k, v in dataclasses.asdict(old).items() if dataclasses.asdict(new)[k] != v)
        raise SpecGenError(f"cannot warm-start across a change of {', '.join(changed)} "
                           f"(only {', '.join(GROWABLE + RELAXED)} may differ, blocks may only be added, and "
                           f"the conv stack's size image_size / detail_factor must stay the same)")
    out = {k: v.float().clone() for k, v in state.items()}
    if old.spectral_code and old.spectral_code_knots != new.spectral_code_knots:
        c, lam = old.feature_dim, old.res_lambda
        for name in ("generator.spectral.weight", "generator.spectral.bias"):
            t = out[name]
            tail = t.shape[1:]                                       # (in,) for the weight, () for the bias
            t = t.reshape(3 * c, old.spectral_code_knots, lam, -1).permute(0, 3, 1, 2)  # (3C, in, A, L)
            t = F.interpolate(t, size=(new.spectral_code_knots, lam), mode="bilinear", align_corners=True)
            out[name] = t.permute(0, 2, 3, 1).reshape(-1, *tail)
    if any(getattr(new, k) > getattr(old, k) for k in ADDED_BLOCKS) or new.detail_factor > old.detail_factor:
        if fresh is None:
            raise SpecGenError("growing blocks or a detail branch needs the new model's initial weights (fresh)")
        out.update({k: v.float().clone() for k, v in fresh.items() if k not in out})
    return out
