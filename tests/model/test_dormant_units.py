"""The dead-unit census, and recycling dormant units without changing the network's output."""

from __future__ import annotations

import math

import pytest
import torch

from specgen_addon.model import Config, SpecGen
from specgen_addon.model.activity import unit_census
from specgen_addon.model.recycle import recycle_dormant, revive_at_boundary, unsupported
from tiny_model import TINY_MODEL

SMALL = {**TINY_MODEL, "spectral_code_knots": 3}

KILLED = {"encoder conv 1": [0, 3], "encoder conv 2": [5], "latent": [1, 2, 7, 30]}


def outputs(model: SpecGen, images: torch.Tensor) -> torch.Tensor:
    g = torch.Generator().manual_seed(1)
    n, b = 200, images.shape[0]
    q = (torch.rand(b, n, generator=g) * math.pi / 2, torch.rand(b, n, generator=g) * math.pi / 2,
         torch.rand(b, n, generator=g) * math.pi, 380 + 400 * torch.rand(b, n, generator=g))
    with torch.no_grad():
        return model(images, *q)


def damaged_model() -> SpecGen:
    """A small network with some units switched off for good (a large negative bias)."""
    torch.manual_seed(0)
    model = SpecGen(Config(**SMALL)).eval()
    convs = [m for m in model.encoder.convs if isinstance(m, torch.nn.Conv2d)]
    with torch.no_grad():
        convs[0].bias[KILLED["encoder conv 1"]] = -1e3
        convs[1].bias[KILLED["encoder conv 2"]] = -1e3
        model.encoder.fc.bias[KILLED["latent"]] = -1e3
    return model


def census(model: SpecGen, images: torch.Tensor) -> dict[str, tuple[int, int]]:
    return {s.stage: (s.ever_active, s.units) for s in unit_census(model, images)}


def test_census_counts_the_units_that_never_switch_on():
    model, images = damaged_model(), torch.rand(16, 3, 32, 32)
    c = census(model, images)
    assert c["encoder conv 1"] == (8 - 2, 8)
    assert c["encoder conv 2"][0] <= 16 - 1
    assert c["latent (encoder output)"][0] <= 32 - 4
    assert list(c)[:3] == ["encoder conv 1", "encoder conv 2", "latent (encoder output)"]
    assert {"decoder seed map", "decoder trunk conv 1", "plane heads (all six)"} <= set(c)


def test_recycling_revives_dead_units_and_leaves_the_output_unchanged():
    model, images = damaged_model(), torch.rand(16, 3, 32, 32)
    fresh = torch.rand(4, 3, 32, 32)           # inputs the census never saw
    before_census, before = census(model, images), outputs(model, fresh)
    renewed = recycle_dormant(model, images, seed=3)
    after_census = census(model, images)
    assert renewed["encoder conv 1"] == 2 and renewed["latent"] >= 4
    assert after_census["encoder conv 1"] == (8, 8)
    assert after_census["latent (encoder output)"][0] > before_census["latent (encoder output)"][0]
    torch.testing.assert_close(outputs(model, fresh), before, rtol=0, atol=1e-6)


def test_recycling_leaves_live_units_alone():
    model, images = damaged_model(), torch.rand(16, 3, 32, 32)
    with torch.no_grad():
        live = (model.encoder.pre_activation(images) > 0).any(0)
    fc_before = model.encoder.fc.weight.detach().clone()
    recycle_dormant(model, images, stages=("latent",))
    renewed = (model.encoder.fc.weight != fc_before).any(1)
    assert renewed[KILLED["latent"]].all()
    assert torch.equal(renewed, ~live)                  # exactly the units that were off
    convs = [m for m in model.encoder.convs if isinstance(m, torch.nn.Conv2d)]
    assert (convs[0].bias[KILLED["encoder conv 1"]] == -1e3).all()   # a stage not asked for


def test_a_recycled_unit_gets_gradient_again():
    model, images = damaged_model(), torch.rand(16, 3, 32, 32)
    outputs_grad(model, images).backward()
    assert model.generator.seed.weight.grad[:, KILLED["latent"]].abs().sum() == 0
    model.zero_grad()
    recycle_dormant(model, images, stages=("latent",))
    outputs_grad(model, images).backward()
    assert (model.generator.seed.weight.grad[:, KILLED["latent"]].abs().sum(0) > 0).all()


def outputs_grad(model: SpecGen, images: torch.Tensor) -> torch.Tensor:
    g = torch.Generator().manual_seed(2)
    b, n = images.shape[0], 100
    q = (torch.rand(b, n, generator=g) * math.pi / 2, torch.rand(b, n, generator=g) * math.pi / 2,
         torch.rand(b, n, generator=g) * math.pi, 380 + 400 * torch.rand(b, n, generator=g))
    return model(images, *q).pow(2).mean()


def test_recycling_refuses_an_unknown_stage():
    with pytest.raises(ValueError, match="unknown stage"):
        recycle_dormant(damaged_model(), torch.rand(2, 3, 32, 32), stages=("planes",))


def test_a_leaky_encoder_keeps_learning_where_a_relu_unit_dies():
    import dataclasses

    torch.manual_seed(0)
    relu = SpecGen(Config(**SMALL))
    leaky = SpecGen(dataclasses.replace(relu.cfg, encoder_negative_slope=0.1))
    leaky.load_state_dict(relu.state_dict())            # same parameters: the slope is not one
    with torch.no_grad():
        for m in (relu, leaky):
            m.encoder.fc.bias[:4] = -1e3                  # four latent units below zero for every input
    images = torch.rand(6, 3, 32, 32)
    for m in (relu, leaky):
        m.encoder(images).sum().backward()
    assert relu.encoder.fc.bias.grad[:4].abs().max() == 0
    assert (leaky.encoder.fc.bias.grad[:4].abs() > 0).all()
    latent = [s for s in unit_census(leaky, images) if s.stage.startswith("latent")][0]
    assert latent.ever_active <= relu.cfg.latent_dim - 4   # the census still counts them as off
    assert unsupported(leaky.cfg) is not None                # and recycling refuses a leaky encoder


def test_revival_at_the_boundary_lets_a_frozen_decoder_keep_reading_the_revived_units():
    model, images = damaged_model(), torch.rand(16, 3, 32, 32)
    fresh = torch.rand(4, 3, 32, 32)
    before, seed_before = outputs(model, fresh), model.generator.seed.weight.detach().clone()
    with torch.no_grad():
        live = (model.encoder.pre_activation(images) > 0).any(0)
    revived = revive_at_boundary(model, images, epsilon=1e-5)
    assert revived["encoder conv 1"] == 2 and revived["latent"] == int((~live).sum())
    assert torch.equal(model.generator.seed.weight, seed_before)         # outgoing columns kept
    assert (model.encoder.fc.weight[~live] == 0).all() and (model.encoder.fc.bias[~live] == 1e-5).all()
    torch.testing.assert_close(outputs(model, fresh), before, rtol=0, atol=1e-3)   # moved by ε only
    model.requires_grad_(False)
    model.encoder.requires_grad_(True)                                    # the decoder frozen
    outputs_grad(model, images).backward()
    assert (model.encoder.fc.weight.grad[KILLED["latent"]].abs().sum(1) > 0).all()
    with pytest.raises(ValueError, match="epsilon"):
        revive_at_boundary(model, images, epsilon=0.0)


def test_the_census_of_a_boosted_model_counts_each_encoder_unit_once_and_feeds_the_decoder_its_latent():
    torch.manual_seed(0)
    cfg = Config(**{**SMALL, "boost_channels": (8,), "boost_width": 8})
    model = SpecGen(cfg).eval()
    images = torch.rand(6, 3, cfg.image_size, cfg.image_size)
    plain = {s.stage: s for s in unit_census(model, images)}
    assert plain["encoder conv 1"].units == cfg.encoder_channels[0]
    with torch.no_grad():                                  # a boost that moves the latent a lot
        model.boost.head[-1].bias.fill_(-50.0)
    boosted = {s.stage: s for s in unit_census(model, images)}
    assert boosted["encoder conv 1"].units == cfg.encoder_channels[0]
    assert boosted["decoder seed map"].mean_active != plain["decoder seed map"].mean_active
