"""Reference renderer against independent truths: closed forms, brute-force quadrature, colour."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from specgen_addon.render import environment_maps as lighting
from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError
from specgen_addon.render import (DistantLight, EnvSampling, Environment, Geometry, Scene,
                                  render_rgb, render_spectral, sphere_geometry)
from specgen_addon.render.analytic import GGXReflector, Lambertian
from specgen_addon.render.environment import direction_to_uv, uv_to_direction

WL = spectra.DEFAULT_WAVELENGTHS_NM


def _sphere_normals(res: int) -> tuple[np.ndarray, np.ndarray]:
    """Sphere normals straight from the pixel-centre definition (independent of geometry.py)."""
    c = (np.arange(res) + 0.5) / res * 2 - 1
    x, y = np.meshgrid(c, -c)
    mask = x * x + y * y < 1
    z = np.sqrt(np.clip(1 - x * x - y * y, 0, None))
    return np.stack([x, y, z], -1), mask


def _blob_environment() -> Environment:
    """A dim sky with a bright warm patch, coarse enough for brute-force quadrature."""
    h, w = 32, 64
    v = 1 - (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    uu, vv = np.meshgrid(u, v)
    d = uv_to_direction(uu, vv)
    blob = np.exp(-np.sum((d - np.array([0.3, 0.6, 0.74])) ** 2, -1) / 0.05)
    rgb = 0.2 + np.stack([6.0 * blob, 4.0 * blob, 2.0 * blob], -1) + 0.1 * (d[..., 1:2] > 0)
    return Environment(rgb.astype(np.float32), name="blob")


def _quadrature(env: Environment, brdf, n: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Brute-force ∫ f L cos dω over every texel of ``env`` (RGB path) for one normal."""
    h, w = env.rgb.shape[:2]
    sub = 4  # 4×4 sub-samples per texel
    v = 1 - (np.arange(h * sub) + 0.5) / (h * sub)
    u = (np.arange(w * sub) + 0.5) / (w * sub)
    uu, vv = np.meshgrid(u, v)
    d = uv_to_direction(uu, vv, env.rotation_rad).reshape(-1, 3)
    el = (vv.reshape(-1) - 0.5) * np.pi
    d_omega = (2 * np.pi / (w * sub)) * (np.pi / (h * sub)) * np.cos(el)
    t = np.cross(n, [0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(n, t)
    frame = np.stack([t, b, n])
    wi_l, wo_l = d @ frame.T, np.broadcast_to(frame @ wo, d.shape)
    up = wi_l[:, 2] > 0
    f = brdf.eval_rgb(wi_l[up], wo_l[up])
    return np.sum(f * env.radiance_rgb(d[up]) * (wi_l[up, 2] * d_omega[up])[:, None], axis=0)


def test_lambertian_sphere_under_distant_light_matches_closed_form():
    res = 48
    rho = np.linspace(0.2, 0.9, WL.size)
    light = DistantLight(direction=(0.4, 0.5, 0.77), irradiance=2.5, illuminant="D65")
    img = render_spectral(Lambertian(rho, WL), sphere_geometry(res), lights=[light], wavelengths_nm=WL)
    n, mask = _sphere_normals(res)
    l = np.array(light.direction) / np.linalg.norm(light.direction)
    cos = np.clip(n @ l, 0, None) * mask
    expected = (rho / np.pi)[None, None, :] * 2.5 * spectra.illuminant_spd("D65", WL) * cos[..., None]
    np.testing.assert_allclose(img.spectral, expected, atol=1e-4, rtol=0)
    assert img.spectral.shape == (res, res, WL.size)


def test_white_furnace_returns_environment_radiance():
    env = Environment.uniform(size=(64, 128))
    img = render_spectral(Lambertian(1.0), sphere_geometry(32), environment=env, wavelengths_nm=WL)
    # A white texel uplifts to D65 of unit luminance (Mallett 2019 basis sums to 1).
    expected = spectra.illuminant_spd("D65", WL)
    ratio = img.spectral[img.mask] / expected
    assert np.abs(ratio - 1).max() < 0.01


def test_white_furnace_without_control_variate_is_unbiased():
    env = Environment.uniform(size=(64, 128))
    img = render_rgb(Lambertian(1.0, rgb=(1, 1, 1)), sphere_geometry(32), environment=env,
                     sampling=EnvSampling(control_variate=False))
    assert abs(img.rgb[img.mask].mean() - 1.0) < 0.01


@pytest.mark.parametrize("control_variate,heuristic", [(True, "balance"), (False, "balance"),
                                                       (True, "power")])
def test_glossy_environment_render_matches_brute_force_quadrature(control_variate, heuristic):
    env = _blob_environment()
    brdf = GGXReflector(alpha=0.3, f0=0.5, kd=0.3, kd_rgb=(0.3, 0.2, 0.1))
    res = 16
    img = render_rgb(brdf, sphere_geometry(res), environment=env,
                     sampling=EnvSampling(control_variate=control_variate,
                                         heuristic=heuristic).scaled(8))
    n, mask = _sphere_normals(res)
    pixels = [(8, 8), (4, 10), (11, 5), (6, 3)]
    for i, j in pixels:
        truth = _quadrature(env, brdf, n[i, j], np.array([0.0, 0.0, 1.0]))
        np.testing.assert_allclose(img.rgb[i, j], truth, rtol=0.02)


def test_flat_reflectance_under_d65_is_neutral():
    light = DistantLight((0.0, 0.3, 1.0), 1.0, "D65")
    img = render_spectral(Lambertian(0.5), sphere_geometry(16), lights=[light])
    rgb = img.rgb[img.mask]
    assert np.all(rgb.max(-1) - rgb.min(-1) <= 1e-3 * rgb.max(-1) + 1e-12)
    env_img = render_spectral(Lambertian(0.5), sphere_geometry(16), environment=Environment.uniform())
    rgb = env_img.rgb[env_img.mask]
    assert np.all(rgb.max(-1) - rgb.min(-1) <= 5e-3 * rgb.max(-1))


def test_rgb_render_of_coloured_lambertian_matches_closed_form():
    res = 24
    albedo = np.array([0.8, 0.4, 0.1])
    img = render_rgb(Lambertian(rgb=tuple(albedo)), sphere_geometry(res),
                     lights=[DistantLight((0.0, 0.0, 1.0), np.pi, "D65")])
    n, mask = _sphere_normals(res)
    expected = albedo * n[..., 2:3] * mask[..., None]  # E = π cancels 1/π; D65 light is white
    np.testing.assert_allclose(img.rgb, expected, atol=2e-3)


def test_environment_direction_convention_lights_the_expected_side():
    # The map is bright only around u = 0.5 + 0/2π … i.e. azimuth 0, which is world +x (right).
    h, w = 32, 64
    rgb = np.full((h, w, 3), 0.01, np.float32)
    rgb[12:20, 30:34] = 50.0
    env = Environment(rgb)
    img = render_rgb(Lambertian(rgb=(1, 1, 1)), sphere_geometry(32), environment=env)
    lum = img.rgb.sum(-1)
    assert lum[16, 28:].sum() > 20 * lum[16, :4].sum()  # right half bright, left rim dark
    u, v = direction_to_uv(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(u[[0, 2]], [0.5, 0.25])
    np.testing.assert_allclose(v, [0.5, 1.0, 0.5])


def test_environment_sampling_density_matches_its_pdf():
    env = _blob_environment()
    xi = np.random.default_rng(1).random((200_000, 2))
    d = env.sample(xi)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-9)
    # E_p[1/p] equals the measure of the support: the whole sphere (every texel is lit).
    assert abs(np.mean(1.0 / env.pdf(d)) / (4 * np.pi) - 1) < 0.02
    # Histogram of sampled texels follows the texel probabilities.
    row, col = env._texel_index(d)
    counts = np.bincount(row * env.rgb.shape[1] + col, minlength=env.rgb.shape[0] * env.rgb.shape[1])
    p = env._distribution()[0].ravel()
    big = p > 1e-3
    np.testing.assert_allclose(counts[big] / len(d), p[big], rtol=0.15)


def test_scene_renders_are_deterministic_and_reusable():
    env = _blob_environment()
    scene = Scene(sphere_geometry(16), [DistantLight((0, 1, 1))], env)
    a = scene.render_spectral(GGXReflector(0.2), WL[::4])
    b = scene.render_spectral(GGXReflector(0.2), WL[::4])
    c = render_spectral(GGXReflector(0.2), sphere_geometry(16), lights=[DistantLight((0, 1, 1))],
                        environment=env, wavelengths_nm=WL[::4])
    np.testing.assert_array_equal(a.spectral, b.spectral)
    # a fresh Scene draws the same directions (equal up to BLAS summation order)
    np.testing.assert_allclose(a.spectral, c.spectral, rtol=1e-12, atol=1e-15)
    assert np.all(a.spectral[~a.mask] == 0) and np.all(a.spectral[a.mask] > 0)


def test_doubling_environment_samples_changes_a_comparison_by_under_half_a_db():
    from specgen_addon.render import metrics

    env = _blob_environment()
    gt, pred = GGXReflector(0.15, 0.5, 0.3), GGXReflector(0.2, 0.4, 0.3)
    psnr = []
    for factor in (1, 2):
        scene = Scene(sphere_geometry(32), environment=env, sampling=EnvSampling().scaled(factor))
        a, b = scene.render_spectral(gt, WL[::5]), scene.render_spectral(pred, WL[::5])
        psnr.append(metrics.spectral_metrics(a.spectral, b.spectral, a.mask).psnr_mean)
    assert abs(psnr[1] - psnr[0]) < 0.5


def test_invalid_inputs_raise_clear_errors():
    g = sphere_geometry(8)
    with pytest.raises(SpecGenError, match="at least one distant light or an environment"):
        render_spectral(Lambertian(), g)
    with pytest.raises(SpecGenError, match="unit length"):
        Geometry(np.full((4, 4, 3), 2.0), np.ones((4, 4), bool))
    with pytest.raises(SpecGenError, match="NaN or Inf"):
        Environment(np.full((4, 8, 3), np.nan, np.float32))
    with pytest.raises(SpecGenError, match="eval_rgb"):
        render_rgb(object(), g, lights=[DistantLight()])


def test_normal_map_geometry_renders_like_the_sphere():
    n, mask = _sphere_normals(16)
    geo = Geometry.from_normal_map(n, mask)
    light = [DistantLight((0.2, 0.3, 1.0))]
    a = render_rgb(Lambertian(rgb=(0.5, 0.5, 0.5)), geo, lights=light).rgb
    b = render_rgb(Lambertian(rgb=(0.5, 0.5, 0.5)), sphere_geometry(16), lights=light).rgb
    np.testing.assert_allclose(a, b, atol=1e-12)


# -- lighting assets --------------------------------------------------------------------------

bpy_missing = importlib.util.find_spec("bpy") is None


@pytest.mark.skipif(bpy_missing, reason="environment maps come from the bpy wheel, not installed")
def test_lighting_lists_name_real_maps_and_keep_held_out_maps_apart():
    available = set(lighting.available_envs())
    assert set(lighting.TRAIN_ENVS) <= available and set(lighting.HELDOUT_ENVS) <= available
    assert not set(lighting.TRAIN_ENVS) & set(lighting.HELDOUT_ENVS)
    env = lighting.load_environment(lighting.HELDOUT_ENVS[0])
    assert env.rgb.ndim == 3 and np.isfinite(env.rgb).all()
    assert abs(env.mean_luminance() - 1.0) < 1e-4  # normalised


def test_lighting_reports_missing_bpy_wheel(monkeypatch):
    monkeypatch.setattr(lighting.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(lighting.LightingAssetError, match="bpy wheel"):
        lighting.studiolights_dir((lighting.wheel_datafiles_dir,))


def test_a_smooth_normal_is_its_corners_at_the_corners_and_their_blend_inside():
    from specgen_addon.render.geometry import smooth_normal

    corners = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    for corner, normal in zip(corners, normals):
        np.testing.assert_allclose(smooth_normal(corner, corners, normals), normal, atol=1e-12)
    centroid = corners.mean(axis=0)
    np.testing.assert_allclose(smooth_normal(centroid, corners, normals), np.ones(3) / np.sqrt(3), atol=1e-12)
    midpoint = (corners[0] + corners[1]) / 2                     # on an edge: the two corners only
    np.testing.assert_allclose(smooth_normal(midpoint, corners, normals), [1 / np.sqrt(2), 0, 1 / np.sqrt(2)],
                               atol=1e-12)
