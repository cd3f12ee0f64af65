"""The refinement's relaxed re-solve: held-out pixels (:mod:`specgen_addon.generate.refine.holdout`) and which
smoothness it loosens (``RefineOptions.relax_axes``)."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.generate.refine import CorrectionBasis, RefineOptions
from specgen_addon.generate.refine.refinement import _normal_equations
from specgen_addon.generate.refine.holdout import block_folds, holdout_error


def test_block_folds_colour_square_blocks_like_a_checkerboard():
    shape = (32, 24)
    ids = np.arange(shape[0] * shape[1])
    folds = block_folds(shape, ids, 8).reshape(shape)
    assert folds[0, 0] == 0 and folds[0, 7] == 0 and folds[7, 7] == 0
    assert folds[0, 8] == 1 and folds[8, 0] == 1 and folds[8, 8] == 0 and folds[31, 23] == 1
    assert folds.sum() * 2 == folds.size                # 4 × 3 blocks: six of each colour
    # a subset of pixels keeps each pixel's own fold
    some = np.array([5, 200, 431, 767])
    assert np.array_equal(block_folds(shape, some, 8), folds.ravel()[some])
    with pytest.raises(ValueError):
        block_folds(shape, ids, 0)


def test_holdout_error_of_a_fixed_prediction_is_its_mean_squared_error():
    """A 'fit' that ignores its data predicts every held-out pixel as it predicts all of them."""
    rng = np.random.default_rng(0)
    design, photo = rng.random((60, 3, 4)), rng.random((60, 3))
    theta = np.array([0.2, 0.5, 0.1, 0.3])
    folds = (np.arange(60) % 2).astype(np.int8)
    expected = float(np.mean((design @ theta - photo) ** 2))
    assert holdout_error(design, photo, folds, lambda d, y: theta) == pytest.approx(expected, rel=1e-12)
    assert holdout_error(design, photo, np.zeros(60, np.int8), lambda d, y: theta) == float("inf")


def test_holdout_error_exposes_a_fit_to_noise_that_the_fitted_pixels_hide():
    """On a photo of pure noise, an unregularised fit with many coefficients reproduces the pixels it
    saw better than predicting zero, and predicts the held-out ones worse."""
    rng = np.random.default_rng(1)
    n, k = 80, 40
    design, photo = rng.normal(size=(n, 3, k)), rng.normal(size=(n, 3))
    folds = (np.arange(n) % 2).astype(np.int8)

    def least_squares(d, y):
        return np.linalg.lstsq(d.reshape(-1, k), y.reshape(-1), rcond=None)[0]

    def zero(d, y):
        return np.zeros(k)

    fitted = least_squares(design, photo)
    assert np.mean((design @ fitted - photo) ** 2) < np.mean(photo ** 2)       # in-sample: the fit wins
    assert holdout_error(design, photo, folds, least_squares) > holdout_error(design, photo, folds, zero)


def _theta_d_ramp(basis: CorrectionBasis) -> np.ndarray:
    """Lobe coefficients that change along θd only (and the other blocks at zero)."""
    na, nb, nl = basis.shape
    x = np.broadcast_to(np.arange(nb, dtype=float)[None, :, None], (na, nb, nl)).ravel()
    return x


def test_smooth_theta_d_sets_the_smoothness_between_theta_d_knots_alone():
    """``smooth_theta_d`` scales the penalty of a correction that varies along θd only, and leaves
    one that varies along θh only to ``smooth``."""
    basis = CorrectionBasis()
    n_lobe, nl = basis.n_lobe, basis.shape[2]
    rng = np.random.default_rng(2)
    design = rng.random((50, 3, 2 * n_lobe + 2 * nl))

    def penalty(x_lobe: np.ndarray, **kw) -> float:
        eq = _normal_equations(design, rng.random((50, 3)), n_lobe, nl, 1.0, basis,
                               RefineOptions(basis=basis, **kw))
        v = np.zeros(design.shape[2])
        v[:n_lobe] = x_lobe
        return float(v @ eq.smooth @ v)

    along_d = _theta_d_ramp(basis)
    na, nb, _ = basis.shape
    along_h = np.broadcast_to(np.arange(na, dtype=float)[:, None, None], basis.shape).ravel()
    assert penalty(along_d, smooth=0.01, smooth_theta_d=3.0) == pytest.approx(
        300.0 * penalty(along_d, smooth=0.01), rel=1e-9)
    assert penalty(along_h, smooth=0.01, smooth_theta_d=3.0) == pytest.approx(
        penalty(along_h, smooth=0.01), rel=1e-9)


def test_refine_options_refuse_an_unknown_relaxation():
    with pytest.raises(SpecGenError, match="relax_axes"):
        RefineOptions(relax_axes="phi_d")
    with pytest.raises(SpecGenError, match="smooth_theta_d"):
        RefineOptions(smooth_theta_d=-1.0)


def _lights_scene(*angles_deg: float, ambient: float = 0.0):
    """A sphere under distant lights at these angles from the camera (in the x–z plane), and an
    ambient term if given."""
    from specgen_addon.render import Environment, Scene, sphere_geometry
    from specgen_addon.render.lights import DistantLight

    lights = [DistantLight((np.sin(np.radians(a)), 0.0, np.cos(np.radians(a))), np.pi) for a in angles_deg]
    env = Environment.uniform((ambient,) * 3) if ambient else None
    return Scene(sphere_geometry(16), lights, env)


@pytest.mark.parametrize("angles,ambient,seen", [
    ((11.0,), 0.0, False),             # one light: every pixel at θd = 5.5°
    ((-40.0, 40.0), 0.0, False),       # two lights mirrored about the view: both at θd = 20°
    ((10.0, 60.0), 0.0, True),         # θd 5° and 30°: two knots told apart
    ((11.0,), 0.05, True),             # an ambient term lights every direction
])
def test_theta_d_is_seen_only_where_the_lights_reach_more_than_one_theta_d(angles, ambient, seen):
    from specgen_addon.generate.refine.refinement import theta_d_seen

    assert theta_d_seen(_lights_scene(*angles, ambient=ambient)) is seen


def test_under_one_distant_light_the_relaxed_fit_keeps_the_theta_d_smoothness(ramp_table):
    """The relaxed fit, forced on, is the θh-only one under one distant light (the photo shows one
    θd), and not once an ambient term lights the other θd."""
    from specgen_addon.generate.refine import apply_correction, diffuse_floor_of, refine_brdf, render_under
    from specgen_addon.photo.photo_lighting import Light, parse_lighting

    basis = CorrectionBasis()
    x = np.ones(basis.shape)
    x[:, :, :] = np.linspace(0.4, 1.8, basis.shape[0])[:, None, None]      # a sharper lobe than the prior's
    truth = apply_correction(ramp_table, diffuse_floor_of(ramp_table), x, np.full(3, 0.7), np.zeros(3), basis)
    forced = dict(clip_level=None, relax_below_db=200.0, relax_holdout=False)
    for ambient, same in ((0.0, True), (0.3, False)):
        lighting = parse_lighting(None, lights=(Light.from_angles(25.0, 10.0),), ambient=ambient)
        photo = render_under(truth, lighting.scene(32), lighting.image_exposure)
        both = refine_brdf(ramp_table, photo, lighting, RefineOptions(**forced))
        theta_h = refine_brdf(ramp_table, photo, lighting, RefineOptions(relax_axes="theta_h", **forced))
        assert both.relaxed and theta_h.relaxed
        assert np.array_equal(both.table.values, theta_h.table.values) is same, ambient
