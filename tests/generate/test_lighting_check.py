"""The lighting warning's reference (specgen_addon.generate.refine.lighting_check): a Lambertian
ball under the best distant lighting of any kind, against analytic Lambertian balls."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.generate.refine.lighting_check import (BRIGHT_SHARE, LIGHTING_MARGIN_DB, any_light_lambertian_db,
                                                          bright_residual_share, lighting_suspect,
                                                          lighting_warning, sh9_basis)


@pytest.fixture(scope="module")
def normals():
    """Unit normals of the camera-facing half of a sphere (z towards the camera)."""
    rng = np.random.default_rng(0)
    n = rng.normal(size=(4000, 3))
    n[:, 2] = np.abs(n[:, 2])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_a_ball_whose_shading_is_second_order_is_reproduced_exactly(normals):
    # ambient + an unclamped directional term + a quadratic term: inside the 9-function span
    rgb = np.stack([0.2 + 0.3 * normals[:, 0] + 0.1 * normals[:, 2] ** 2,
                    0.25 + 0.2 * normals[:, 1], 0.3 + 0.1 * normals[:, 0] * normals[:, 1]], 1)
    assert any_light_lambertian_db(rgb, normals) > 100.0


def test_a_lambertian_ball_under_one_distant_light_is_reproduced_to_within_a_few_percent(normals):
    light = np.array([0.4, 0.5, 0.77])
    light /= np.linalg.norm(light)
    shade = np.maximum(normals @ light, 0.0)
    rgb = shade[:, None] * np.array([0.6, 0.5, 0.4])
    db = any_light_lambertian_db(rgb, normals)
    assert 28.0 < db < 60.0                  # good, not exact: the clamp is not second order
    # a wrongly placed light is far worse than the reference
    wrong = np.maximum(normals @ (light * [-1, 1, 1]), 0.0)[:, None] * np.array([0.6, 0.5, 0.4])
    rel = np.mean((wrong - rgb) ** 2, axis=0) / np.percentile(rgb, 99.9) ** 2
    assert -10 * np.log10(rel).mean() < db - LIGHTING_MARGIN_DB


def test_a_clipped_highlight_is_left_out_of_the_fit_and_clipped_in_the_reference(normals):
    shade = np.repeat((0.3 + 0.9 * normals[:, 2])[:, None], 3, axis=1)   # peaks at 1.2
    photo = np.minimum(shade, 1.0)                                         # the camera clips at 1
    unclipped = photo.max(1) < 1.0
    assert not unclipped.all()
    as_camera = any_light_lambertian_db(photo, normals, unclipped, full_scale=1.0)
    assert as_camera > 100.0
    assert any_light_lambertian_db(photo, normals) < as_camera - 20.0     # fitted to the clip as if real
    assert any_light_lambertian_db(photo, normals, fitted=np.zeros(len(photo), bool)) is None


def test_the_lighting_is_suspect_only_when_low_and_far_under_the_reference_or_missing_a_highlight():
    assert not lighting_suspect(31.0, 45.0, 0.9, 30.0)        # reproduces well: not questioned
    assert not lighting_suspect(25.0, 30.0, 0.02, 30.0)       # low, but so is any Lambertian
    assert lighting_suspect(20.0, 30.0, 0.02, 30.0)           # far under a matte ball's own light
    assert lighting_suspect(25.0, 26.0, 0.8, 30.0)            # the residual sits on the highlight
    assert lighting_suspect(25.0, None, None, 30.0)           # no figure: the threshold alone
    assert lighting_suspect(15.0, 16.0, 0.05, 30.0)           # far under: nothing explains it


def test_the_warning_says_which_figure_named_the_lighting():
    assert lighting_warning(31.0, 45.0, 0.9, 30.0) is None
    far = lighting_warning(20.0, 30.0, 0.02, 30.0)
    assert "does not explain this photo" in far and "30.0 dB" in far
    highlight = lighting_warning(25.0, 26.0, 0.8, 30.0)
    assert "80% of its error on the photo's brightest pixels" in highlight


def test_the_assumed_studio_is_questioned_whenever_the_photo_is_not_reproduced():
    # figures that clear a light the user gave do not clear the studio no one gave
    assert lighting_warning(25.0, 30.0, 0.02, 30.0) is None
    studio = lighting_warning(25.0, 30.0, 0.02, 30.0, studio=True)
    assert "canonical studio" in studio and "give the room's light" in studio
    assert lighting_warning(31.0, 30.0, 0.02, 30.0, studio=True) is None


def test_the_bright_share_is_the_residual_on_the_brightest_five_percent():
    rows = np.repeat(np.linspace(0.0, 1.0, 1000)[:, None], 3, axis=1)
    at_peak = rows.copy()
    at_peak[-20:] += 0.3                                      # misses only the brightest 2 %
    assert bright_residual_share(rows, at_peak) == pytest.approx(1.0)
    spread = rows + 0.05                                      # misses every pixel alike
    assert bright_residual_share(rows, spread) == pytest.approx(0.05, abs=0.002)
    assert bright_residual_share(rows, rows) is None
    assert BRIGHT_SHARE > 0.05


def test_sh9_basis_spans_nine_independent_functions(normals):
    assert np.linalg.matrix_rank(sh9_basis(normals)) == 9
