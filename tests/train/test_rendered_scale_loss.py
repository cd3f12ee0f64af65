"""The rendered-scale training term: its geometry and its value against analytic cases."""

from __future__ import annotations

import numpy as np
import torch

from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import mu_law_encode
from specgen_addon.train.losses import foreshortening, inverse_mu_law, rendered_scale_loss
from tiny_training import twice_and_without


def test_foreshortening_is_the_smaller_cosine_of_the_two_directions():
    rng = np.random.default_rng(0)
    th, td, pd = rng.random((3, 2000)) * np.array([[np.pi / 2], [np.pi / 2], [np.pi]])
    wi, wo = io_from_half_diff(th, td, pd)
    expected = np.clip(np.minimum(wi[:, 2], wo[:, 2]), 0.0, None)
    got = foreshortening(*(torch.from_numpy(a) for a in (th, td, pd))).numpy()
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_inverse_mu_law_undoes_the_table_encoding():
    f = np.array([0.0, 1e-3, 0.3, 7.0, 900.0])
    r = torch.from_numpy(mu_law_encode(f, 255.0))
    np.testing.assert_allclose(inverse_mu_law(r, 255.0).numpy(), f, rtol=1e-9, atol=1e-12)


def test_a_brightness_error_costs_its_square_relative_to_the_brightest_point():
    """f̂ = s·f everywhere: the term is (s − 1)² · mean((f·cos / max f·cos)²), exactly."""
    rng = np.random.default_rng(1)
    f = rng.lognormal(-1.0, 1.5, size=(2, 300))
    cos_w = rng.random((2, 300))
    valid = np.ones_like(f)
    s = 1.25
    enc = lambda a: torch.from_numpy(mu_law_encode(a, 255.0))  # noqa: E731
    got = rendered_scale_loss(enc(s * f), enc(f), torch.from_numpy(valid), torch.from_numpy(cos_w), 255.0)
    rel = f * cos_w / (f * cos_w).max(axis=1, keepdims=True)
    assert abs(float(got) - (s - 1) ** 2 * np.mean(rel ** 2)) < 1e-9
    assert float(rendered_scale_loss(enc(f), enc(f), torch.from_numpy(valid), torch.from_numpy(cos_w),
                                     255.0)) == 0.0


def test_points_below_the_horizon_do_not_count():
    f = np.full((1, 4), 0.5)
    pred = f.copy()
    pred[0, 3] = 50.0                          # wrong, but masked
    valid = np.array([[1.0, 1.0, 1.0, 0.0]])
    enc = lambda a: torch.from_numpy(mu_law_encode(a, 255.0))  # noqa: E731
    ones = torch.ones(1, 4, dtype=torch.float64)
    got = rendered_scale_loss(enc(pred), enc(f), torch.from_numpy(valid), ones, 255.0)
    assert float(got) == 0.0


def test_a_run_with_the_term_is_bit_identical_for_a_seed_and_differs_from_one_without(tmp_path):
    (sa, sb, sc), (a, _, c) = twice_and_without(tmp_path, steps=4, linear_loss_weight=2.0)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert any(not torch.equal(sa[k], sc[k]) for k in sa)
    assert a.history[0]["spec"] > c.history[0]["spec"]   # the same first batch, plus the term
