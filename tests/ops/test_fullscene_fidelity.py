"""Full Scene shows the generated material: SpecGen surfaces against the reference renderer.

The Full Scene render draws a SpecGen material's direct light from the exact lookups and leaves
only the bounces to the fitted closure stack (ops/exact_direct.py); the closure fit weighs table
entries by the direction pairs they stand for and reports its rendered colour error
(specgen_addon/bake/closure_fit/fit_check.py). Truth: the NumPy reference renderer (specgen_addon.render) on
the same sphere under the same D65 sun (as bench/fullscene_vs_reference.py).
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from specgen_addon.bake.closure_fit import fit_closures, ggx_lobe
from specgen_addon.bake.closure_fit.closures import cell_volumes
from specgen_addon.bake.closure_fit.fit_check import WARN_DELTA_E, rendered_fit_error
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([420.0, 480.0, 540.0, 600.0, 660.0, 720.0])
RHO = np.interp(WL, [400, 550, 720], [0.1, 0.45, 0.6])
SUN = (0.35, 0.45, 0.82)
#: The target of the Full Scene render against the reference renderer.
MAX_DELTA_E, MAX_ENERGY_OFF = 1.0, 0.03


def _outside_the_model(th, td, pd):
    """A body that brightens with the half angle θd (which Lambert and a view Fresnel cannot
    follow) under a sharp, tall GGX peak: a closure fit misses it, as it missed the example."""
    wi, wo = io_from_half_diff(th, td, pd)
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    body = above * RHO / np.pi * (0.1 + 3.0 * np.sin(td)[:, None] ** 2)
    return body + ggx_lobe(wi, wo, 0.12)[:, None] * np.interp(WL, [400, 720], [0.3, 0.1])


def _inside_the_model(th, td, pd):
    wi, wo = io_from_half_diff(th, td, pd)
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    return above * RHO / np.pi + ggx_lobe(wi, wo, 0.3)[:, None] * 0.2


@pytest.fixture(scope="module")
def outside_table() -> BRDFTable:
    return BRDFTable.tabulate(_outside_the_model, WL)


# ------------------------------------------------------------------------- no bpy
def test_cell_volumes_integrate_the_hemisphere_measure():
    vh, vd = cell_volumes()
    assert vh.sum() == pytest.approx(1.0)          # ∫ sin θh dθh over [0, π/2]
    assert vd.sum() == pytest.approx(0.5)          # ∫ sin θd cos θd dθd
    assert vh[:30].sum() < 0.06                    # the first third of the θh rows: < 10°


def test_rendered_fit_error_is_small_inside_the_model_and_flags_a_material_outside_it(outside_table):
    inside = fit_closures(BRDFTable.tabulate(_inside_the_model, WL), check=True)
    assert inside.rendered_error < 0.1
    outside = fit_closures(outside_table, check=True)
    assert outside.rendered_error > WARN_DELTA_E           # the user is warned ...
    assert outside.max_error < 0.05                        # ... where the residual looked fine
    assert outside.rendered_error == pytest.approx(rendered_fit_error(outside, outside_table))


def test_the_checked_fit_keeps_the_weighting_that_renders_closer(outside_table):
    from specgen_addon.bake.closure_fit.closures import WEIGHTINGS

    errors = [rendered_fit_error(fit_closures(outside_table, weighting=w), outside_table) for w in WEIGHTINGS]
    assert fit_closures(outside_table, check=True).rendered_error == pytest.approx(min(errors))
    with pytest.raises(Exception, match="unknown weighting"):
        fit_closures(outside_table, weighting="uniform")


# ------------------------------------------------------------------------- Cycles
@pytest.fixture(scope="module")
def addon() -> SimpleNamespace:
    """bpy and the add-on's modules these renders use, loaded as Blender loads them; skips
    without the bpy module."""
    bpy = pytest.importorskip("bpy")
    from addon_modules import addon_module

    return SimpleNamespace(bpy=bpy, bake=addon_module("specgen_addon.bake.lookup"),
                           render=addon_module("ops.render"), scene=addon_module("ops.scene"),
                           fullscene=addon_module("ops.render_fullscene"),
                           convert=addon_module("ops.scene_convert"), demo=addon_module("ops.demo_scenes"))


def _sphere_scene(addon: SimpleNamespace, info, name: str, sun, res: int):
    """An empty .blend with the bench's sphere wearing SpecGen material ``name`` of lookup ``info``,
    an orthographic camera sampling pixel centres and a sun of irradiance π from ``sun``; gives
    (scene, sphere)."""
    sc, sphere = addon.scene.new_reference_sphere_scene(lambda: addon.render.make_material(name, info), sun)
    sc.render.resolution_x = sc.render.resolution_y = res
    return sc, sphere


def _sphere_render(addon: SimpleNamespace, table: BRDFTable, tmp_path: Path, res: int = 40, samples: int = 8):
    """(reference, Full Scene, closures alone, warnings) for ``table`` on the bench's sphere."""
    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry

    info = addon.bake.bake_atlas(table, tmp_path / "t.exr")
    ref = render_spectral(table, sphere_geometry(res), lights=[DistantLight(SUN, np.pi)],
                          wavelengths_nm=table.wavelengths).spectral
    out, warnings = {}, []
    for exact in (True, False):
        sc, _ = _sphere_scene(addon, info, "SpecGen fid", SUN, res)
        sc.cycles.samples, sc.cycles.use_denoising = samples, False
        job = addon.fullscene.FullSceneRenderJob(sc, None, table.wavelengths, exact_direct=exact,
                                                 warn=warnings.append, log=lambda _: None)
        out[exact] = job.run()
    return ref, out[True], out[False], warnings, info.closures


def _score(ref: np.ndarray, got: np.ndarray, wl: np.ndarray) -> tuple[float, float]:
    from specgen_addon.render.photo_reproduction import delta_e2000, photo_scale
    from specgen_addon.render.spectral_exr import linear_srgb_preview

    mask = ref.sum(-1) > 0
    a, b = linear_srgb_preview(ref, wl)[mask], linear_srgb_preview(got, wl)[mask]
    return delta_e2000(a, b, photo_scale(a)), float(got[mask].sum() / ref[mask].sum())


@pytest.mark.blender
def test_full_scene_renders_a_material_the_closures_cannot_hold(outside_table, tmp_path, addon):
    ref, full, closures, warnings, fit = _sphere_render(addon, outside_table, tmp_path)
    de, energy = _score(ref, full, WL)
    assert de <= MAX_DELTA_E and abs(energy - 1) <= MAX_ENERGY_OFF, (de, energy)
    de_closures, energy_closures = _score(ref, closures, WL)   # what the closure stack alone shows
    assert de_closures > MAX_DELTA_E or abs(energy_closures - 1) > MAX_ENERGY_OFF, (de_closures,
                                                                                  energy_closures)
    named = [w for w in warnings if "'SpecGen fid'" in w and "ΔE2000" in w]
    assert fit.rendered_error > WARN_DELTA_E and named, warnings
    assert any("Exact mode" in w for w in named)           # closures alone: the better mode named


@pytest.mark.blender
@pytest.mark.slow
def test_full_scene_renders_the_example_photos_material_as_the_reference(repo_dir, tmp_path, addon):
    from specgen_addon.generate import pipeline

    table = pipeline.generate(repo_dir / "examples" / "sphere.png").table   # network + refinement
    ref, full, _, warnings, fit = _sphere_render(addon, table, tmp_path, res=48)
    de, energy = _score(ref, full, table.wavelengths)
    assert de <= MAX_DELTA_E and abs(energy - 1) <= MAX_ENERGY_OFF, (de, energy)
    assert (fit.rendered_error > WARN_DELTA_E) == any("'SpecGen fid'" in w for w in warnings), warnings


@pytest.mark.blender
def test_exact_direct_light_changes_only_the_specgen_surface_of_an_ordinary_scene(outside_table, tmp_path,
                                                                                  addon):
    bpy = addon.bpy
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    info = addon.bake.bake_atlas(outside_table, tmp_path / "t.exr")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = addon.render.make_material("SpecGen fid", info)
    w, h = 48, 32
    sc = addon.demo.ordinary_scene(samples=4, size=(w, h), specgen_material=mat)
    before = addon.convert.fingerprint()
    stacks, warnings = {}, []
    for exact in (True, False):
        job = addon.fullscene.FullSceneRenderJob(sc, None, WL, exact_direct=exact, warn=warnings.append,
                                                 log=lambda _: None, show_result=False)
        stacks[exact] = job.run()
    assert addon.convert.fingerprint() == before
    # the world (two Background nodes) is beyond the exact lookups: said, and left to the closures
    assert any("world's light on SpecGen surfaces" in m for m in warnings), warnings
    changed = np.abs(stacks[True] - stacks[False]).sum(-1) > 0
    sphere = bpy.data.objects["SpecGen"]
    corners = [world_to_camera_view(sc, sc.camera, sphere.matrix_world @ Vector(c)) for c in sphere.bound_box]
    xs = [c.x * w for c in corners]
    ys = [(1 - c.y) * h for c in corners]
    box = np.zeros((h, w), bool)
    box[max(0, int(min(ys)) - 1):int(max(ys)) + 2, max(0, int(min(xs)) - 1):int(max(xs)) + 2] = True
    assert changed.any() and not (changed & ~box).any()


@pytest.mark.blender
def test_exact_mode_matches_the_reference_with_the_sun_behind_the_camera(tmp_path, addon):
    # θd ≈ 0 is a tile's first row: a bicubic lookup read the tile above it (6-15 % dark)
    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry

    table = BRDFTable.tabulate(_inside_the_model, WL)
    info = addon.bake.bake_atlas(table, tmp_path / "t.exr")
    sc, _ = _sphere_scene(addon, info, "SpecGen retro", (0.0, 0.0, 1.0), 24)
    got = addon.render.SpectralRenderJob(sc, None, samples=2, resolution=(24, 24)).run()
    ref = render_spectral(table, sphere_geometry(24), lights=[DistantLight((0.0, 0.0, 1.0), np.pi)],
                          wavelengths_nm=WL).spectral
    assert abs(_score(ref, got, WL)[1] - 1) <= MAX_ENERGY_OFF


@pytest.mark.blender
def test_other_materials_of_a_specgen_object_keep_their_own_light(outside_table, tmp_path, addon):
    bpy = addon.bpy
    info = addon.bake.bake_atlas(outside_table, tmp_path / "t.exr")
    sc, sphere = _sphere_scene(addon, info, "SpecGen fid", SUN, 24)
    sphere.data.materials.append(addon.demo.principled("red", (0.8, 0.1, 0.1)))
    for poly in sphere.data.polygons:          # the left half (camera's view) is red Principled
        poly.material_index = int(poly.center.x < 0)
    sc.cycles.samples, sc.cycles.use_denoising = 4, False
    stacks = {exact: addon.fullscene.FullSceneRenderJob(sc, None, WL, exact_direct=exact, warn=lambda _: None,
                                                        log=lambda _: None, show_result=False).run()
              for exact in (True, False)}
    diff = np.abs(stacks[True] - stacks[False]).sum(-1)
    assert diff[:, :10].max() == 0 and diff[:, 14:].max() > 0     # red half untouched, SpecGen half exact
    assert "SpecGen holdout" not in bpy.data.materials
