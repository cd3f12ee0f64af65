"""Where the sphere sits: the training jitter and the evaluation's displaced inputs."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch

from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo.sphere_image import prepare_sphere_array
from specgen_addon.train.augment import jitter_framing, offgrid_photo_crop, reframe
from specgen_addon.evaluation.trained_network import displaced_input
from specgen_addon.train.loop import TrainConfig
from tiny_training import twice_and_without

needs_bpy = pytest.mark.skipif(importlib.util.find_spec("bpy") is None,
                               reason="the canonical input's environment map ships in the bpy wheel")


def test_a_whole_pixel_shift_moves_the_image_exactly():
    img = np.random.default_rng(0).random((3, 16, 16)).astype(np.float32)
    out = reframe(img, 2.0, -1.0)
    np.testing.assert_array_equal(out[:, 2:, :-1], img[:, :-2, 1:])
    np.testing.assert_array_equal(reframe(img, 0.0, 0.0), img)


def test_a_half_pixel_shift_averages_neighbours():
    img = np.zeros((1, 8, 8), np.float32)
    img[0, 4, 4] = 1.0
    out = reframe(img, 0.0, 0.5)
    assert out[0, 4, 4] == pytest.approx(0.5) and out[0, 4, 5] == pytest.approx(0.5)
    assert out.sum() == pytest.approx(1.0)


def test_scaling_is_about_the_image_centre():
    img = np.zeros((1, 9, 9), np.float32)
    img[0, 4, 6] = 1.0                       # two pixels right of the centre
    out = reframe(img, 0.0, 0.0, 2.0)
    assert tuple(np.argwhere(out[0] == out[0].max())[0]) == (4, 8)
    assert out[0, 4, 4] == 0.0


def test_jitter_is_drawn_from_the_generator_within_its_bounds():
    img = np.random.default_rng(1).random((3, 16, 16)).astype(np.float32)
    a = jitter_framing(img, np.random.default_rng(5), 0.5, 0.02)
    rng = np.random.default_rng(5)
    dy, dx = rng.uniform(-0.5, 0.5, size=2)
    scale = 1.0 + rng.uniform(-0.02, 0.02)
    np.testing.assert_array_equal(a, reframe(img, dy, dx, scale))
    assert abs(dy) <= 0.5 and abs(dx) <= 0.5 and abs(scale - 1.0) <= 0.02


def test_jittered_training_is_bit_identical_for_a_seed_and_differs_from_unjittered(tmp_path):
    (sa, sb, sc), _ = twice_and_without(tmp_path, input_jitter_px=0.5, input_scale_jitter=0.02)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert any(not torch.equal(sa[k], sc[k]) for k in sa)


def test_a_negative_jitter_is_refused():
    with pytest.raises(SpecGenError, match="input_jitter_px must be"):
        TrainConfig.from_dict({"input_jitter_px": -0.5})
    with pytest.raises(SpecGenError, match="input_scale_jitter must be"):
        TrainConfig.from_dict({"input_scale_jitter": -0.1})


def _disc_image(size: int = 64) -> np.ndarray:
    yy, xx = (np.mgrid[0:size, 0:size] + 0.5 - size / 2) / (size / 2)
    inside = xx * xx + yy * yy < 1.0
    img = np.zeros((size, size, 3), np.float32)
    img[inside] = np.stack([0.2 + 0.25 * (xx[inside] + 1), 0.3 * np.ones(inside.sum()),
                            0.6 - 0.2 * yy[inside]], -1)
    return img


def test_a_whole_pixel_displacement_gives_the_pipeline_the_same_crop():
    """The measurement's zero point: moved by whole pixels inside a border, the sphere is found
    and cropped exactly as the framed original."""
    img = _disc_image()
    ref = prepare_sphere_array(img, size=64)
    moved = displaced_input(img, 3.0)
    assert moved.shape == (96, 96, 3)
    np.testing.assert_allclose(prepare_sphere_array(moved, size=64), ref, atol=1e-6)
    off = prepare_sphere_array(displaced_input(img, 0.5), size=64)
    assert np.abs(off - ref).max() > 1e-3    # off the pixel grid, the crop differs


def test_an_offgrid_crop_is_what_the_pipeline_makes_of_a_photo_moved_off_the_grid():
    """Without finder error, the augmentation equals the loader's crop of the same photo (the
    sphere finder's error on this disc is far below the 0.07 px the training draws)."""
    from scipy.ndimage import shift

    img = _disc_image()
    rng = np.random.default_rng(7)
    out = offgrid_photo_crop(img.transpose(2, 0, 1), rng, 0.0).transpose(1, 2, 0)
    dy, dx = np.random.default_rng(7).uniform(0.0, 1.0, size=2)
    photo = shift(np.pad(img, ((4, 4), (4, 4), (0, 0))), (dy, dx, 0.0), order=1)
    assert 0 < dy < 1 and 0 < dx < 1
    diff = np.abs(out - prepare_sphere_array(photo, size=64)).max(-1)
    yy, xx = (np.mgrid[0:64, 0:64] + 0.5 - 32) / 32
    rr = np.hypot(xx, yy)
    assert diff[rr < 0.9].max() < 2e-3        # inside: the finder's few hundredths of a pixel
    assert diff.max() < 0.15                   # the outline pixels, steep, move most
    assert np.abs(out - img).max() > 1e-3
    assert np.all(out[rr >= 1.0] == 0.0)


def test_offgrid_training_is_bit_identical_for_a_seed_and_differs_from_the_plain_run(tmp_path):
    (sa, sb, sc), _ = twice_and_without(tmp_path, input_offgrid_fraction=1.0)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert any(not torch.equal(sa[k], sc[k]) for k in sa)


@pytest.mark.parametrize("key,value", [("input_offgrid_fraction", 1.5), ("input_offgrid_fraction", -0.1),
                                       ("input_finder_error_px", -0.1)])
def test_bad_offgrid_settings_are_refused(key, value):
    with pytest.raises(SpecGenError, match=key):
        TrainConfig.from_dict({key: value})


@needs_bpy
def test_an_antialiased_input_is_area_sampled_and_found_where_it_was_put():
    """4× rendered and box-filtered, moved a quarter pixel: the outline pixels are partly covered,
    and the pipeline's finder puts the sphere within a tenth of a pixel of where it is."""
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render.analytic import Lambertian
    from specgen_addon.evaluation.trained_network import antialiased_input

    img = antialiased_input(Lambertian(0.6), shift_px=0.25, border_px=4, size=64)
    assert img.shape == (72, 72, 3)
    lum = img.sum(-1)
    assert np.any((lum > 0) & (lum < 0.5 * lum.max()))           # partly covered outline pixels
    mask, contrast = input_image._foreground(img)
    cx, cy, r = input_image._refined_circle(contrast, input_image._circle_of_mask(mask, fit_outline=True))
    assert abs(cx - 36.25) < 0.1 and abs(cy - 36.25) < 0.1 and abs(r - 32.0) < 0.1, (cx, cy, r)
