"""The spectral code's angle knots, and warm starts that grow a one-knot model into a knotted one."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from specgen_addon.common.errors import SpecGenError
from specgen_addon.model import Config, SpecGen, load_weights, save_weights
from specgen_addon.model.grow import can_grow, grow_state_dict
from tiny_model import TINY_MODEL

SMALL = TINY_MODEL


def queries(n: int = 300, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(2, n, generator=g) * math.pi / 2, torch.rand(2, n, generator=g) * math.pi / 2,
            torch.rand(2, n, generator=g) * math.pi, 380 + 400 * torch.rand(2, n, generator=g))


def lively(model: SpecGen) -> SpecGen:
    """Spectral-code weights large enough that the code matters to the output."""
    torch.nn.init.normal_(model.generator.spectral.weight, std=0.3)
    torch.nn.init.normal_(model.generator.spectral.bias, std=0.3)
    return model.eval()


def code_added(knots: int) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """What the spectral code adds to each spectral plane of a lively model, and the raw code
    ``(1, 3 planes, C, knots, res_lambda)``."""
    torch.manual_seed(0)
    model = lively(SpecGen(Config(**SMALL, spectral_code_knots=knots)))
    image = torch.rand(1, 3, 32, 32)
    with torch.no_grad():
        with_code = model.planes(image)
        latent, colour = model.encoder(image), model.encoder.colour(image)
        code = model.generator.spectral(torch.cat([latent, colour], 1)).view(1, 3, 16, knots, 6)
        model.generator.spectral = None
        without = model.planes(image)
    return {n: with_code[n] - without[n] for n in ("e1", "e2", "e3")}, code


def test_one_knot_profile_is_constant_along_each_angle_axis():
    added, _ = code_added(1)
    for a in added.values():
        assert torch.allclose(a, a[:, :, :1].expand_as(a), atol=1e-6)


def test_knotted_profile_varies_along_the_angle_axis_through_its_knots():
    planes, code = code_added(3)
    added = planes["e2"]                                                     # rows: 8 θd texels
    assert added.std(dim=2).mean() > 0.05                                    # not angle-constant
    assert torch.allclose(added[:, :, 0], code[:, 1, :, 0], atol=1e-5)      # first knot at θd = 0
    assert torch.allclose(added[:, :, -1], code[:, 1, :, -1], atol=1e-5)    # last knot at θd = π/2


def test_growing_one_knot_weights_keeps_the_network_function_exactly():
    torch.manual_seed(0)
    old = lively(SpecGen(Config(**SMALL, spectral_code_knots=1)))
    new_cfg = Config(**SMALL, spectral_code_knots=5)
    new = SpecGen(new_cfg)
    new.load_state_dict(grow_state_dict(old.state_dict(), old.cfg, new_cfg))
    new.eval()
    image = torch.rand(2, 3, 32, 32)
    th, td, pd, lam = queries()
    with torch.no_grad():
        assert torch.allclose(old(image, th, td, pd, lam), new(image, th, td, pd, lam), atol=1e-5)
        assert torch.allclose(old(image, th, td, pd, None), new(image, th, td, pd, None), atol=1e-5)


def test_warm_start_refuses_any_other_change_by_name():
    old = Config(**SMALL, spectral_code_knots=1)
    new = dataclasses.replace(old, spectral_code_knots=4, mlp_hidden=(8, 8))
    assert not can_grow(old, new)
    assert can_grow(old, dataclasses.replace(old, spectral_code_knots=4))
    with pytest.raises(SpecGenError, match="mlp_hidden"):
        grow_state_dict(SpecGen(old).state_dict(), old, new)


def test_weights_written_before_the_knots_load_as_one_knot(tmp_path):
    torch.manual_seed(0)
    model = SpecGen(Config(**SMALL, spectral_code_knots=1))
    path = save_weights(model, tmp_path / "old.pt")
    payload = torch.load(path, weights_only=True)
    del payload["config"]["spectral_code_knots"]                               # as older files were
    torch.save(payload, path)
    assert load_weights(path).cfg.spectral_code_knots == 1


def test_bad_knot_counts_are_refused():
    for bad in (0, -2, 2.5, "3"):
        with pytest.raises(SpecGenError, match="spectral_code_knots"):
            Config(**SMALL, spectral_code_knots=bad)


def test_growing_residual_blocks_keeps_the_network_function_and_then_trains_them():
    torch.manual_seed(0)
    old = lively(SpecGen(Config(**SMALL, spectral_code_knots=1)))
    new_cfg = Config(**SMALL, spectral_code_knots=3, latent_res_blocks=2, trunk_res_blocks=1)
    new = SpecGen(new_cfg)
    new.load_state_dict(grow_state_dict(old.state_dict(), old.cfg, new_cfg, fresh=new.state_dict()))
    image = torch.rand(2, 3, 32, 32)
    th, td, pd, lam = queries()
    with torch.no_grad():
        assert torch.allclose(old(image, th, td, pd, lam), new.eval()(image, th, td, pd, lam), atol=1e-5)
    # the added blocks are not dead: their output layers get gradients
    new.train()
    new(image, th, td, pd, lam).pow(2).mean().backward()
    assert new.encoder.res[1].body[2].weight.grad.abs().sum() > 0
    assert new.generator.trunk[-1].body[2].weight.grad.abs().sum() > 0


def test_residual_blocks_may_be_added_but_not_removed_and_need_the_fresh_weights():
    small = Config(**SMALL, latent_res_blocks=1)
    assert can_grow(small, dataclasses.replace(small, latent_res_blocks=3, trunk_res_blocks=2))
    assert not can_grow(small, dataclasses.replace(small, latent_res_blocks=0))
    with pytest.raises(SpecGenError, match="latent_res_blocks"):
        grow_state_dict(SpecGen(small).state_dict(), small, dataclasses.replace(small, latent_res_blocks=0))
    with pytest.raises(SpecGenError, match="fresh"):
        grow_state_dict(SpecGen(small).state_dict(), small, dataclasses.replace(small, trunk_res_blocks=1))


def test_bad_residual_block_counts_are_refused():
    for name in ("latent_res_blocks", "trunk_res_blocks", "trunk_upsample_stages"):
        for bad in (-1, 1.5, "2", True):
            with pytest.raises(SpecGenError, match=name):
                Config(**SMALL, **{name: bad})


def test_adding_a_detail_branch_at_twice_the_image_size_keeps_the_network_function():
    import numpy as np

    from specgen_addon.model.runtime.inference import resample_square

    torch.manual_seed(0)
    old = lively(SpecGen(Config(**SMALL)))
    new_cfg = Config(**{**SMALL, "image_size": 64}, detail_factor=2)
    new = SpecGen(new_cfg)
    new.load_state_dict(grow_state_dict(old.state_dict(), old.cfg, new_cfg, fresh=new.state_dict()))
    big = np.random.default_rng(1).random((2, 64, 64, 3), dtype=np.float32) * 1.5
    small = torch.from_numpy(np.stack([resample_square(b, 32) for b in big]))   # the input pipeline's 64 → 32
    th, td, pd, lam = queries()
    with torch.no_grad():
        assert torch.allclose(old(small, th, td, pd, lam),
                              new.eval()(torch.from_numpy(big.transpose(0, 3, 1, 2).copy()), th, td, pd, lam),
                              atol=1e-5)
    # the branch is not dead: its zero-initialised last layer gets a gradient
    new.train()
    new(torch.from_numpy(big.transpose(0, 3, 1, 2).copy()), th, td, pd, lam).pow(2).mean().backward()
    assert new.encoder.detail[-1].weight.grad.abs().sum() > 0


def test_detail_branch_growth_needs_the_same_conv_stack_size_and_never_removes_a_branch():
    old = Config(**SMALL)
    assert can_grow(old, dataclasses.replace(old, image_size=64, detail_factor=2))
    assert can_grow(old, dataclasses.replace(old, image_size=128, detail_factor=4))
    assert not can_grow(old, dataclasses.replace(old, image_size=64))                  # stack would see 64²
    assert not can_grow(dataclasses.replace(old, image_size=64, detail_factor=2), old)  # branch removed
    with pytest.raises(SpecGenError, match="image_size"):
        grow_state_dict(SpecGen(old).state_dict(), old, dataclasses.replace(old, image_size=64))
    with pytest.raises(SpecGenError, match="fresh"):
        new = dataclasses.replace(old, image_size=64, detail_factor=2)
        grow_state_dict(SpecGen(old).state_dict(), old, new)


def test_bad_detail_factors_are_refused():
    for bad in (0, 3, 1.5, "2", True):
        with pytest.raises(SpecGenError, match="detail_factor"):
            Config(**SMALL, detail_factor=bad)
    with pytest.raises(SpecGenError, match="divisible"):
        Config(**SMALL, detail_factor=16)


def test_growing_trunk_upsample_stages_keeps_the_network_function_and_then_trains_them():
    torch.manual_seed(0)
    old = lively(SpecGen(Config(**SMALL, spectral_code_knots=2)))
    new_cfg = Config(**SMALL, spectral_code_knots=2, trunk_upsample_stages=2)
    new = SpecGen(new_cfg)
    new.load_state_dict(grow_state_dict(old.state_dict(), old.cfg, new_cfg, fresh=new.state_dict()))
    image = torch.rand(2, 3, 32, 32)
    th, td, pd, lam = queries()
    with torch.no_grad():
        trunk, _ = new.generator.trunk_and_code(new.encoder(image))
        assert trunk.shape[-2:] == (29, 29)                                  # 8×8 → 15×15 → 29×29
        assert torch.allclose(old(image, th, td, pd, lam), new.eval()(image, th, td, pd, lam), atol=1e-5)
    new.train()
    new(image, th, td, pd, lam).pow(2).mean().backward()
    assert new.generator.refine[-1].block.body[2].weight.grad.abs().sum() > 0
    assert not can_grow(new_cfg, old.cfg)                                    # stages are never removed


def test_config_files_accept_no_added_blocks_and_refuse_too_many(tmp_path):
    from specgen_addon.train.loop import validate_train_config

    path = tmp_path / "c.json"
    path.write_text('{"model": {"latent_res_blocks": 0, "trunk_res_blocks": 0, "trunk_upsample_stages": 0}}')
    validate_train_config(path)
    path.write_text('{"model": {"trunk_upsample_stages": 9}}')
    with pytest.raises(SpecGenError, match="trunk_upsample_stages must be between 0 and 4"):
        validate_train_config(path)


def test_weights_that_name_the_retired_boost_encoder_switched_off_still_load():
    d = Config(**SMALL).to_dict()
    assert Config.from_dict({**d, "boost_channels": [], "boost_width": 96}) == Config(**SMALL)


def test_a_config_that_turns_the_retired_boost_encoder_on_is_refused_in_one_sentence():
    with pytest.raises(SpecGenError, match="boost_channels = \\[8, 8\\] asks for an experiment"):
        Config.from_dict({**Config(**SMALL).to_dict(), "boost_channels": [8, 8]})
