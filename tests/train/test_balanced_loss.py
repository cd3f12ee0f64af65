"""The per-material log-balanced MSE (``material_balance: "log"``): its value, its gradient, its checks."""

from __future__ import annotations

import pytest
import torch

from specgen_addon.common.errors import SpecGenError
from specgen_addon.train.loop import TrainConfig
from specgen_addon.train.losses import balanced_mse, masked_mse


def _rows(seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(4, 64, generator=g, dtype=torch.float64)
    # rows fitted to very different levels, as a batch of easy and hard materials is
    noise = torch.randn(4, 64, generator=g, dtype=torch.float64) * torch.tensor([[1e-3], [1e-2], [3e-2], [1e-1]],
                                                                                dtype=torch.float64)
    valid = (torch.rand(4, 64, generator=g) > 0.2).double()
    return target + noise, target, valid


def test_balanced_mse_has_the_plain_mse_as_its_value() -> None:
    pred, target, valid = _rows()
    assert torch.allclose(balanced_mse(pred, target, valid, 0.1), masked_mse(pred, target, valid))


def test_balanced_mse_gradient_is_that_of_the_mean_log_of_each_materials_mse() -> None:
    pred, target, valid = _rows(1)
    p1 = pred.clone().requires_grad_(True)
    balanced_mse(p1, target, valid, 0.1).backward()
    p2 = pred.clone().requires_grad_(True)
    per = ((p2 - target) ** 2 * valid).sum(1) / valid.sum(1)
    level = per.mean().detach()
    (level * torch.log(per + 0.1 * level).mean()).backward()
    assert torch.allclose(p1.grad, p2.grad, rtol=1e-10, atol=1e-14)


def test_balanced_mse_weighs_a_well_fitted_material_more_than_the_plain_mse_does() -> None:
    pred, target, valid = _rows(2)
    grads = []
    for fn in (lambda p: balanced_mse(p, target, valid, 0.1), lambda p: masked_mse(p, target, valid)):
        p = pred.clone().requires_grad_(True)
        fn(p).backward()
        grads.append(p.grad.abs().sum(1) / (pred - target).abs().mul(valid).sum(1))
    ratio = grads[0] / grads[1]
    # row 0 is fitted best, row 3 worst: the balance scales their gradients up and down respectively
    assert ratio[0] > 1 > ratio[3]
    assert torch.all(ratio[:-1] > ratio[1:])


@pytest.mark.parametrize("d, words", [({"material_balance": "median"}, "material_balance"),
                                      ({"material_balance": "log", "balance_floor": 0.0}, "balance_floor"),
                                      ({"balance_floor": -1.0}, "balance_floor")])
def test_bad_material_balance_settings_are_refused_by_name(d: dict, words: str) -> None:
    with pytest.raises(SpecGenError, match=words):
        TrainConfig.from_dict(d)
