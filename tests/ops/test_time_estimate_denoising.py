"""The Full Scene time estimate counts the scene's denoiser: its cost per render and per pixel,
measured by one-sample test renders with denoising at two sizes, times the renders that denoise."""

from __future__ import annotations

import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.cycles_time_estimate import RenderCost


def test_denoising_cost_is_separated_into_per_render_and_per_pixel_parts():
    plain = RenderCost(overhead_s=0.4, rate_s=2e-6)
    truth = RenderCost(overhead_s=0.4, rate_s=2e-6, denoise_overhead_s=0.15, denoise_rate_s=3e-7)
    sizes = (1024, 4096)
    times = tuple(truth.render_s(p, 1) + truth.denoise_s(p) for p in sizes)
    cost = plain.with_denoising(sizes, times)
    assert cost.denoise_overhead_s == pytest.approx(0.15) and cost.denoise_rate_s == pytest.approx(3e-7)
    pixels = 1920 * 1080
    assert cost.predict(15, pixels, 16, denoised=14) == pytest.approx(
        15 * plain.render_s(pixels, 16) + 14 * (0.15 + 3e-7 * pixels))
    assert cost.predict(15, pixels, 16) == pytest.approx(plain.predict(15, pixels, 16))
    # the adaptive share keeps the denoiser's cost
    assert cost.with_adaptive(256, 64, cost.render_s(256, 16)).denoise_rate_s == cost.denoise_rate_s
    noisy = plain.with_denoising(sizes, (plain.render_s(1024, 1) + 0.2, plain.render_s(4096, 1) + 0.19))
    assert noisy.denoise_rate_s > 0 and noisy.denoise_overhead_s >= 0   # never a negative rate
    with pytest.raises(SpecGenError):
        plain.with_denoising((1024, 1024), (1.0, 1.0))


@pytest.mark.blender
def test_the_estimate_of_a_denoised_scene_times_its_denoiser(blank_scene):
    bpy = pytest.importorskip("bpy")
    from addon_modules import addon_module

    scene_mod = addon_module("ops.scene")
    settings = addon_module("ops.render_settings")
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    scene_mod.add_camera(sc)
    scene_mod.add_mesh(sc, "sphere")
    scene_mod.add_sun(sc, (0.3, -0.4, 0.8))
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 128, 96, 100
    sc.cycles.samples, sc.cycles.use_adaptive_sampling = 4, False
    sc.cycles.use_denoising = True
    cost = settings.measure_cost(sc)
    assert sc.cycles.use_denoising and sc.cycles.samples == 4     # the scene's own, restored
    assert cost.denoise_s(128 * 96) > 0
    seconds, text = settings.estimate(sc, 6, cost)                  # 2 band groups, no SpecGen
    assert "denoising 2 of them" in text and "each" in text, text
    sc.cycles.use_denoising = False
    plain, text = settings.estimate(sc, 6, cost)
    assert "denoising" not in text
    assert seconds == pytest.approx(plain + 2 * cost.denoise_s(128 * 96))
