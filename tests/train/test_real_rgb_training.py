"""Real RGB measurements in joint training: targets, augmentation, the loss on the RGB side, folds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from tiny_training import FAST_TRAIN as FAST, TRAIN_MODEL as SMALL, material_sets as sets

from specgen_addon.common.errors import SpecGenError
from specgen_addon.model import Config, SpecGen
from specgen_addon.brdf.table import mu_law_encode
from specgen_addon.train.data import TrainingMaterial
from specgen_addon.train.loop import MaterialSet, TrainConfig, total_loss, train
from specgen_addon.train.real_rgb import (
    REAL_BANDS_NM,
    RealSource,
    augment_gains,
    real_files,
    real_loss,
    srgb_projection,
)


class Tinted:
    """A Lambertian RGB 'measurement' of albedo ``rgb``."""

    def __init__(self, rgb=(0.6, 0.2, 0.1)):
        self.rgb = np.asarray(rgb, float)
        self.is_spectral = False

    def eval_rgb(self, wi, wo):
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.tile(self.rgb / np.pi, (len(wi), 1))


def sphere_photo(rgb, size: int = 64) -> np.ndarray:
    y, x = np.mgrid[-1:1:size * 1j, -1:1:size * 1j]
    disk = ((x ** 2 + y ** 2) <= 0.8).astype(np.float32)
    return (disk[..., None] * np.asarray(rgb, np.float32) * 0.5).astype(np.float32)


def source(rgbs, **kw) -> RealSource:
    mats = [TrainingMaterial(f"real{i}", Tinted(c), False) for i, c in enumerate(rgbs)]
    return RealSource(mats, [sphere_photo(c) for c in rgbs], per_step=kw.pop("per_step", 2), **kw)


def test_projection_takes_a_flat_spectrum_to_grey():
    """D65's white maps to sRGB white: a BRDF of the same value in every band projects to (a, a, a)."""
    m = srgb_projection()
    assert m.shape == (len(REAL_BANDS_NM), 3)
    assert np.allclose(0.3 * np.ones(len(REAL_BANDS_NM)) @ m, 0.3, atol=2e-3)


def test_white_balance_gains_keep_exposure_and_draw_nothing_when_off():
    rng = np.random.default_rng(0)
    g = augment_gains(rng, 0.0, 0.2)
    assert np.isclose(np.prod(g), 1.0) and not np.allclose(g, 1.0)
    rng2 = np.random.default_rng(5)
    assert np.array_equal(augment_gains(rng2, 0.0, 0.0), np.ones(3))
    assert rng2.random() == np.random.default_rng(5).random()


def test_real_targets_are_mu_law_rgb_of_the_measurement_scaled_by_the_same_gain_as_the_photo():
    src = source([(0.6, 0.2, 0.1)], per_step=1, exposure_stops=0.5, white_balance=0.2, png_p=0.0)
    b = src.batch(seed=3, step=7, image_size=32, n_angles=64, mu=255.0)
    plain = dataclasses.replace(src, exposure_stops=0.0, white_balance=0.0).batch(3, 7, 32, 64, 255.0)
    v = b.valid[0]
    f = np.expm1(b.target_rgb[0][v] * np.log1p(255.0)) / 255.0          # a constant BRDF: every row alike
    f0 = np.expm1(plain.target_rgb[0][plain.valid[0]] * np.log1p(255.0)) / 255.0
    gain = f.mean(axis=0) / f0.mean(axis=0)
    assert np.allclose(f, f.mean(axis=0), rtol=1e-4) and np.allclose(f0.mean(axis=0), np.array([0.6, 0.2, 0.1]) / np.pi)
    assert not np.allclose(gain, 1.0)
    lit = plain.images[0].sum(axis=(1, 2))
    assert np.allclose(b.images[0].sum(axis=(1, 2)) / lit, gain, rtol=1e-3)  # the photo, the same gain
    assert np.allclose(b.target_grey[0][v], mu_law_encode(f.mean(axis=1)), atol=1e-5)


def test_real_batches_are_a_pure_function_of_seed_and_step():
    src = source([(0.6, 0.2, 0.1), (0.1, 0.5, 0.3), (0.3, 0.3, 0.3)], exposure_stops=0.5, white_balance=0.1)
    a, b = src.batch(1, 4, 32, 32, 255.0), src.batch(1, 4, 32, 32, 255.0)
    assert a.names == b.names and np.array_equal(a.images, b.images) and np.array_equal(a.target_rgb, b.target_rgb)
    assert len(a.names) == 2
    c = src.batch(1, 5, 32, 32, 255.0)
    assert not np.array_equal(a.target_rgb, c.target_rgb)


def test_real_loss_supervises_colour_not_only_the_grey_response():
    """Two measurements of the same grey level but different colours give different losses for one
    prediction: the colour term sees what the paper's grey RGB term cannot."""
    torch.manual_seed(0)
    model = SpecGen(Config(**SMALL))
    br = source([(0.6, 0.2, 0.1)], per_step=1, png_p=0.0).batch(0, 0, 32, 64, 255.0)
    bg = source([(0.3, 0.3, 0.3)], per_step=1, png_p=0.0).batch(0, 0, 32, 64, 255.0)
    bg = dataclasses.replace(bg, images=br.images)              # the same photo, so one prediction
    assert np.allclose(br.target_grey, bg.target_grey, atol=1e-6)
    with torch.no_grad():
        lr, _ = real_loss(model, br)
        lg, _ = real_loss(model, bg)
    assert abs(float(lr) - float(lg)) > 1e-4


def test_real_loss_trains_the_spectral_branch_through_the_projection():
    torch.manual_seed(0)
    model = SpecGen(Config(**SMALL))
    b = source([(0.6, 0.2, 0.1)], per_step=1, png_p=0.0).batch(0, 0, 32, 64, 255.0)
    loss, tv = real_loss(model, b)
    (loss + tv).backward()
    grads = {n: p.grad for n, p in model.named_parameters() if p.grad is not None and p.grad.abs().sum() > 0}
    assert any(n.startswith("generator") for n in grads) and any(n.startswith("mapping") for n in grads)


def test_total_loss_weighs_the_real_group():
    t = TrainConfig(real_weight=3.0, tv_weight=0.0)
    one = (torch.tensor(1.0), torch.tensor(0.0))
    loss, parts = total_loss(t, one, None, one)
    assert float(loss) == pytest.approx(4.0) and parts["real"] == pytest.approx(1.0)


def test_training_with_real_files_lowers_their_loss(tmp_path):
    spec, _, val = sets()
    src = source([(0.6, 0.2, 0.1), (0.1, 0.5, 0.3)], png_p=0.0)
    tcfg = TrainConfig(**{**FAST, "steps": 40, "lr": 3e-3, "rgb_materials_per_step": 0,
                          "real_materials_per_step": 2})
    res = train(Config(**SMALL), tcfg, spec, MaterialSet([], []), val, tmp_path, show_progress=False, real=src)
    real = [r["real"] for r in res.history]
    assert np.mean(real[-5:]) < 0.5 * np.mean(real[:5])


def test_excluded_files_never_reach_training_and_unknown_names_are_refused(tmp_path):
    for name in ("a_rgb", "b_rgb", "c_rgb"):
        (tmp_path / f"{name}.bsdf").write_bytes(b"x")
    assert [p.stem for p in real_files(tmp_path, ["b_rgb"])] == ["a_rgb", "c_rgb"]
    with pytest.raises(SpecGenError, match="zz_rgb"):
        real_files(tmp_path, ["zz_rgb"])


def test_config_keys_are_checked():
    with pytest.raises(SpecGenError):
        TrainConfig(real_materials_per_step=-1).validate()
    with pytest.raises(SpecGenError):
        TrainConfig(real_exposure_jitter=float("nan")).validate()
    TrainConfig(real_materials_per_step=2, corpus_train_limit=10).validate()
