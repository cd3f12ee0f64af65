"""SpecGen network: shapes, gradients, AFF per the paper's equations, μ-law, weights files."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from specgen_addon.common.errors import SpecGenError, WeightsError
from specgen_addon.model import Config, SpecGen, count_parameters, load_weights, save_weights
from specgen_addon.model.fusion import AFF
from specgen_addon.model.planes import PLANE_NAMES, normalized_coords, project, sample_plane
from specgen_addon.brdf.table import mu_law_decode, mu_law_encode
from tiny_model import TINY_MODEL

SMALL = TINY_MODEL


def random_queries(b: int, n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    th = torch.rand(b, n, generator=g) * math.pi / 2
    td = torch.rand(b, n, generator=g) * math.pi / 2
    pd = torch.rand(b, n, generator=g) * math.pi
    lam = 380 + 400 * torch.rand(b, n, generator=g)
    return th, td, pd, lam


def test_default_model_fits_the_cpu_budget():
    n = count_parameters(SpecGen(Config()))
    assert 1_000_000 <= n <= 5_000_000


def test_planes_and_predictions_have_configured_shapes(tiny_network):
    model = tiny_network()
    planes = model.planes(torch.rand(3, 3, 32, 32))
    assert list(planes) == list(PLANE_NAMES)
    for name, (rows, cols) in model.cfg.plane_shapes.items():
        assert planes[name].shape == (3, 16, rows, cols)
    th, td, pd, lam = random_queries(3, 50)
    assert model.query(planes, th, td, pd, lam).shape == (3, 50)
    assert model.query(planes, th, td, pd, None).shape == (3, 50)


@pytest.mark.parametrize("fusion", ["aff", "hadamard"])
def test_a_training_step_runs_wholly_on_the_models_device(fusion, tiny_network):
    """Every tensor the network makes lives on its parameters' device, so it trains on a GPU:
    torch's shape-only "meta" device refuses a host tensor as a GPU does (the GPU check of
    bench/gpu_check.sh found AFF's constant maps made on the host)."""
    model = tiny_network(fusion=fusion, spectral_code_knots=3, trunk_upsample_stages=1).to("meta")
    planes = model.planes(torch.rand(2, 3, 32, 32, device="meta"))
    q = [t.to("meta") for t in random_queries(2, 40)]
    loss = model.query(planes, *q).pow(2).mean() + model.query(planes, *q[:3], None).pow(2).mean()
    (loss + model.tv_loss(planes)).backward()
    assert all(p.grad is not None and p.grad.device.type == "meta" for p in model.parameters())


def test_gradients_reach_all_six_planes(tiny_network):
    model = tiny_network()
    planes = model.planes(torch.rand(2, 3, 32, 32))
    for p in planes.values():
        p.retain_grad()
    th, td, pd, lam = random_queries(2, 200)
    model.query(planes, th, td, pd, lam).pow(2).mean().backward()
    for name, p in planes.items():
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_rgb_branch_gradients_reach_spectral_planes_through_the_lambda_average(tiny_network):
    model = tiny_network()
    planes = model.planes(torch.rand(1, 3, 32, 32))
    for p in planes.values():
        p.retain_grad()
    th, td, pd, _ = random_queries(1, 100)
    model.query(planes, th, td, pd, None).sum().backward()
    for name in ("e1", "e2", "e3"):
        g = planes[name].grad
        # every λ column receives the same share of the averaged feature's gradient
        assert torch.allclose(g, g[..., :1].expand_as(g), atol=1e-7)
        assert g.abs().sum() > 0


def test_aff_branch_weights_are_a_softmax_over_six(tiny_network):
    model = tiny_network()
    feats = torch.randn(7, 11, 6, 16)
    w = model.fusion.branch_weights(feats)
    assert w.shape == (7, 11, 6)
    assert torch.all(w > 0)
    assert torch.allclose(w.sum(-1), torch.ones(7, 11), atol=1e-6)


def test_aff_statistic_is_the_gap_of_the_summed_branch_convs(tiny_config):
    """Eq. (6)-(7) literally (3×3 conv per branch on the 1×H×W view, sum, GAP) vs the fast form."""
    aff = AFF(tiny_config)
    torch.nn.init.normal_(aff.branch_convs.weight)
    feats = torch.randn(40, 6, 16)
    maps = feats.reshape(40, 6, 4, 4)
    literal = sum(torch.nn.functional.conv2d(maps[:, k:k + 1], aff.branch_convs.weight[k:k + 1],
                                             aff.branch_convs.bias[k:k + 1], padding=1)
                  for k in range(6))[:, 0].mean(dim=(1, 2))
    m, b = aff.gap_functionals()
    assert torch.allclose(torch.einsum("nkc,kc->n", feats, m) + b, literal, atol=1e-5)
    assert torch.allclose(aff.hybrid_map(feats).mean(dim=(-1, -2)), literal, atol=1e-5)


def test_aff_output_is_the_weighted_sum_of_the_input_features(tiny_network):
    model = tiny_network()
    feats = torch.randn(5, 6, 16)
    w = model.fusion.branch_weights(feats)
    expected = sum(w[:, k:k + 1] * feats[:, k] for k in range(6))
    assert torch.allclose(model.fusion(feats), expected, atol=1e-6)


def test_hadamard_fusion_is_the_elementwise_product(tiny_network):
    model = tiny_network(fusion="hadamard")
    feats = torch.randn(5, 6, 16)
    assert torch.allclose(model.fusion(feats), feats.prod(dim=1))
    th, td, pd, lam = random_queries(1, 20)
    assert torch.isfinite(model(torch.rand(1, 3, 32, 32), th, td, pd, lam)).all()


def test_theta_h_is_sqrt_warped_like_merl(tiny_config):
    cfg = tiny_config
    rows = cfg.res_theta_h
    plane = torch.arange(rows, dtype=torch.float32).reshape(1, 1, rows, 1).expand(1, 1, rows, 3).contiguous()
    i = torch.arange(rows, dtype=torch.float32)
    theta_h = (i / (rows - 1)) ** 2 * math.pi / 2          # texel centres in √ space
    u = normalized_coords(theta_h[None], theta_h[None] * 0, theta_h[None] * 0, None, cfg)
    got = sample_plane(plane, u["theta_h"], torch.zeros_like(u["theta_h"]))[0, :, 0]
    assert torch.allclose(got, i, atol=1e-4)


def test_phi_d_folds_by_reciprocity(tiny_config):
    cfg = tiny_config
    pd = torch.tensor([[0.3, 0.3 + math.pi, 0.3 - math.pi]])
    u = normalized_coords(pd * 0, pd * 0, pd, None, cfg)["phi_d"]
    assert torch.allclose(u, u[:, :1].expand_as(u), atol=1e-6)


def test_rgb_features_are_the_mean_of_features_at_the_lambda_texels(tiny_config):
    cfg = tiny_config
    torch.manual_seed(1)
    planes = {n: torch.randn(1, 16, *s) for n, s in cfg.plane_shapes.items()}
    th, td, pd, _ = random_queries(1, 9)
    u = normalized_coords(th, td, pd, None, cfg)
    grey = project(planes, u)
    per_band = []
    for l in torch.linspace(-1, 1, cfg.res_lambda):
        per_band.append(project(planes, {**u, "lambda": torch.full_like(th, float(l))}))
    mean = torch.stack(per_band).mean(0)
    assert torch.allclose(grey[:, :, 3:], mean[:, :, 3:], atol=1e-5)   # spectral features
    assert torch.allclose(grey[:, :, :3], per_band[0][:, :, :3])        # spatial ones unchanged


def test_mu_law_round_trip():
    r = np.concatenate([np.linspace(0, 2, 101), np.logspace(-6, 4, 50)])
    rp = mu_law_encode(r)
    assert np.all(np.diff(rp[:101]) > 0)
    assert np.allclose(mu_law_decode(rp), r, rtol=1e-9, atol=1e-12)
    assert math.isclose(float(mu_law_encode(np.array(1.0))), 1.0)


def test_config_rejects_inconsistent_sizes():
    with pytest.raises(SpecGenError, match="aff_map_hw"):
        Config(feature_dim=32, aff_map_hw=(4, 4))
    with pytest.raises(SpecGenError, match="fusion"):
        Config(fusion="dot")
    with pytest.raises(SpecGenError, match="unknown model config keys"):
        Config.from_dict({"planes": 3})


def test_weights_round_trip(tmp_path, tiny_network):
    model = tiny_network()
    path = save_weights(model, tmp_path / "w.pt", meta={"seed": 3})
    loaded = load_weights(path)
    assert loaded.cfg == model.cfg and loaded.meta == {"seed": 3}
    for (k, a), (_, b) in zip(model.state_dict().items(), loaded.state_dict().items()):
        assert torch.equal(a, b), k


def test_corrupt_weights_raise_a_clear_error(tmp_path, tiny_network):
    path = save_weights(tiny_network(), tmp_path / "w.pt")
    data = path.read_bytes()
    (tmp_path / "cut.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(WeightsError, match="cut.pt: not a readable weights file"):
        load_weights(tmp_path / "cut.pt")
    (tmp_path / "text.pt").write_text("hello")
    with pytest.raises(WeightsError, match="not a readable weights file"):
        load_weights(tmp_path / "text.pt")
    with pytest.raises(WeightsError, match="not found"):
        load_weights(tmp_path / "missing.pt")


def test_mismatched_weights_raise_a_clear_error(tmp_path, tiny_network):
    model = tiny_network()
    payload = torch.load(save_weights(model, tmp_path / "w.pt"), weights_only=True)
    payload["config"]["feature_dim"] = 32
    payload["config"]["aff_map_hw"] = [4, 8]
    torch.save(payload, tmp_path / "mismatch.pt")
    with pytest.raises(WeightsError, match="do not match their configuration"):
        load_weights(tmp_path / "mismatch.pt")
    torch.save({"state_dict": {}}, tmp_path / "other.pt")
    with pytest.raises(WeightsError, match="not a SpecGen weights file"):
        load_weights(tmp_path / "other.pt")
    with pytest.raises(WeightsError, match="different model configuration"):
        load_weights(tmp_path / "w.pt", expect=Config())


def test_half_precision_weights_load_as_float32_close_to_the_original(tmp_path, tiny_network):
    model = tiny_network()
    small = save_weights(model, tmp_path / "h.pt", half=True)
    full = save_weights(model, tmp_path / "f.pt")
    assert small.stat().st_size < 0.7 * full.stat().st_size
    loaded = load_weights(small)
    for (k, a), (_, b) in zip(model.state_dict().items(), loaded.state_dict().items()):
        assert b.dtype == a.dtype
        assert torch.allclose(a, b, rtol=1e-3, atol=1e-4), k
