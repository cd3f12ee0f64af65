"""Full-scene spectral mode: Cycles path-traces the whole scene, three bands per render.

Headless with the bpy module and real Cycles. Truths: Cycles' own RGB render of the same scene
(the uplift is linear, so the spectral stack projected back to RGB must agree), the exact mode
(tabulated BRDF evaluated in OSL, itself checked against the reference renderer), Blender's own
blackbody colours, and the scene's datablocks before the render.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import batch  # noqa: E402
from addon_modules import addon_module, psnr as _psnr  # noqa: E402  (after the bpy skip)
bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
fullscene = addon_module("ops.render_fullscene")
convert = addon_module("ops.scene_convert")
scene_mod = addon_module("ops.scene")
demo = addon_module("ops.demo_scenes")
core_errors = addon_module("specgen_addon.common.errors")

from specgen_addon.spectral import spectra  # noqa: E402
from specgen_addon.bake import scene_uplift as uplift  # noqa: E402
from specgen_addon.bake.closure_fit import ggx_lobe  # noqa: E402
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff  # noqa: E402
from specgen_addon.brdf.table import BRDFTable  # noqa: E402

WL = np.array([410.0, 480.0, 540.0, 600.0, 660.0, 720.0])
RGB_WL = spectra.wavelength_grid(380.0, 780.0, 21)


def _rgb_render(sc) -> np.ndarray:
    """Plain RGB Cycles render of ``sc`` (linear Combined, RGBA)."""
    path = Path(bpy.app.tempdir or "/tmp") / f"specgen_rgb_{os.getpid()}.exr"
    with fullscene._RenderSettings(sc):
        bpy.ops.render.render(write_still=False, scene=sc.name)
        bpy.data.images["Render Result"].save_render(str(path), scene=sc)
    try:
        return fullscene._read_combined(path)
    finally:
        path.unlink(missing_ok=True)


def _camera(sc, location=(0.0, -7.0, 3.0), rotation=(1.2, 0.0, 0.0)):
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    sc.collection.objects.link(cam)
    cam.location, cam.rotation_euler = location, rotation
    sc.camera = cam
    return cam


def _principled(name, rgb, **inputs):
    return demo.principled(name, rgb, **inputs)


def _ordinary_scene(samples: int = 64, size=(48, 32)):
    return demo.ordinary_scene(samples, size)


# ------------------------------------------------------------------------- truths
def test_spectral_stack_projected_to_rgb_matches_a_plain_rgb_cycles_render():
    sc = _ordinary_scene()
    before = convert.fingerprint()
    job = fullscene.FullSceneRenderJob(sc, None, RGB_WL)
    stack = job.run()
    assert convert.fingerprint() == before                      # every datablock restored
    assert stack.shape == (32, 48, RGB_WL.size)
    assert len(job.timings["render_s"]) == 7                     # 21 bands, three per render
    rgb = _rgb_render(sc)[..., :3]
    projected = spectra.spectral_to_linear_srgb(stack, RGB_WL)
    psnr = _psnr(projected, rgb)
    assert psnr >= 35.0, psnr


@pytest.mark.parametrize("kind", ["lambert+ggx", "fresnel-plastic", "per-band-roughness"])
def test_full_scene_mode_matches_the_exact_mode_on_a_specgen_only_scene(tmp_path, kind):
    from specgen_addon.bake.closure_fit.closures import fresnel_dielectric

    rho = np.interp(WL, [400, 550, 720], [0.15, 0.7, 0.35])
    spec = np.interp(WL, [400, 720], [0.9, 0.2])
    rough = np.geomspace(0.15, 0.5, WL.size)                   # a lobe that widens with λ

    def brdf(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)              # wi: light, wo: view (as the OSL)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        if kind == "fresnel-plastic":  # the Fresnel node / Mix Shader closures
            f = fresnel_dielectric(wo[:, 2], 1.5)[:, None]
            return above * rho / np.pi * (1 - f) + ggx_lobe(wi, wo, 0.3)[:, None] * spec * f * 5
        if kind == "per-band-roughness":  # one Glossy node per channel of a band group
            return above * rho / np.pi + np.stack([ggx_lobe(wi, wo, r) for r in rough], -1) * spec
        return above * rho / np.pi + ggx_lobe(wi, wo, 0.35)[:, None] * spec

    info = bake.bake_atlas(BRDFTable.tabulate(brdf, WL), tmp_path / "a.exr", tolerance=1e-6)
    assert info.closures.max_error < 0.01
    assert info.closures.per_band_lobes.any() == (kind == "per-band-roughness")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    mat = render.make_material("SpecGen t", info)
    assert ("SpecGen Lobe 1 (G)" in mat.node_tree.nodes) == (kind == "per-band-roughness")
    scene_mod.add_mesh(sc, "sphere").data.materials.append(mat)
    sc.cycles.filter_width = 0.01
    scene_mod.add_sun(sc, (0.35, 0.45, 0.82), irradiance=np.pi)
    scene_mod.add_sun(sc, (-0.6, 0.2, 0.5), irradiance=1.0)
    sc.render.resolution_x = sc.render.resolution_y = 32
    sc.cycles.samples = 64                                       # light-selection noise of 2 suns
    sc.cycles.use_denoising = False
    exact = render.SpectralRenderJob(sc, None, samples=4, resolution=(32, 32)).run()
    full = fullscene.FullSceneRenderJob(sc, None, WL).run()
    psnr = [_psnr(full[..., b], exact[..., b]) for b in range(WL.size)]
    assert min(psnr) >= 35.0, psnr


def test_light_blackbody_follows_planck_like_blenders_own_colour():
    light = bpy.data.lights.new("bb", "SUN")
    light.use_temperature = True
    wl = spectra.wavelength_grid(380.0, 780.0, 81)
    for kelvin in (2000.0, 4000.0, 6500.0, 10000.0):
        light.temperature = kelvin
        ours = spectra.spectral_to_linear_srgb(uplift.blackbody_spectrum(kelvin, wl), wl)
        np.testing.assert_allclose(ours, light.temperature_color[:], rtol=0.03, atol=0.01)
    bpy.data.lights.remove(light)


def test_blackbody_light_and_emission_render_like_cycles(blank_scene):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.render.resolution_x = sc.render.resolution_y = 24
    sc.cycles.samples, sc.cycles.use_denoising = 32, False
    bpy.ops.mesh.primitive_plane_add(size=10)
    bpy.context.active_object.data.materials.append(_principled("white", (0.8, 0.8, 0.8)))
    bpy.ops.mesh.primitive_cube_add(size=1, location=(1.5, 0, 0.5))
    glow = bpy.data.materials.new("glow")
    t = glow.node_tree
    t.nodes.clear()
    em, bb, out = (t.nodes.new(n) for n in ("ShaderNodeEmission", "ShaderNodeBlackbody",
                                            "ShaderNodeOutputMaterial"))
    bb.inputs["Temperature"].default_value = 2500.0
    t.links.new(bb.outputs[0], em.inputs["Color"])
    t.links.new(em.outputs[0], out.inputs["Surface"])
    bpy.context.active_object.data.materials.append(glow)
    sun = scene_mod.add_sun(sc, (0.2, 0.3, 0.9), 3.0)
    sun.data.use_temperature, sun.data.temperature = True, 3200.0
    _camera(sc, (0.0, -6.0, 4.0), (0.9, 0.0, 0.0))
    before = convert.fingerprint()
    stack = fullscene.FullSceneRenderJob(sc, None, RGB_WL).run()
    assert convert.fingerprint() == before
    psnr = _psnr(spectra.spectral_to_linear_srgb(stack, RGB_WL), _rgb_render(sc)[..., :3])
    assert psnr >= 30.0, psnr   # Planck vs Blender's fitted blackbody RGB: ~1–3 % apart


# ------------------------------------------------------------------------- scene settings
def test_output_follows_resolution_border_transparency_and_writes_alpha(tmp_path):
    from specgen_addon.render.spectral_exr import read_spectral_exr

    sc = _ordinary_scene(samples=2, size=(40, 30))
    sc.render.resolution_percentage = 50                          # 20 × 15
    sc.render.film_transparent = True
    job = fullscene.FullSceneRenderJob(sc, tmp_path / "s.exr", np.array([450.0, 550.0, 650.0, 700.0]))
    stack = job.run()
    assert stack.shape == (15, 20, 4)
    assert job.alpha.min() == 0.0 and job.alpha.max() == pytest.approx(1.0)  # sky transparent
    import OpenEXR

    with OpenEXR.File(str(tmp_path / "s.exr"), separate_channels=True) as f:
        names = set(f.parts[0].channels)
        np.testing.assert_array_equal(np.asarray(f.parts[0].channels["A"].pixels), job.alpha)
    assert {"A", "R", "G", "B", "S0.450,000000nm", "S0.700,000000nm"} <= names
    assert read_spectral_exr(tmp_path / "s.exr").values.shape == (15, 20, 4)
    sc.render.use_border, sc.render.use_crop_to_border = True, True
    sc.render.border_min_x, sc.render.border_max_x = 0.0, 0.5
    sc.render.border_min_y, sc.render.border_max_y = 0.0, 1.0
    cropped = fullscene.FullSceneRenderJob(sc, None, np.array([550.0])).run()
    assert cropped.shape == (15, 10, 1)
    assert sc.render.resolution_percentage == 50 and sc.render.film_transparent


def test_cancel_restores_the_scene_and_writes_nothing(tmp_path):
    sc = _ordinary_scene(samples=1, size=(16, 16))
    before = convert.fingerprint()
    engine, persistent = sc.render.engine, sc.render.use_persistent_data
    job = fullscene.FullSceneRenderJob(sc, tmp_path / "s.exr", RGB_WL)
    steps = job.steps()
    next(steps)
    next(steps)                                                  # one band group rendered
    assert convert.fingerprint() != before                       # the scene is converted now
    job.cancel()
    with pytest.raises(core_errors.Cancelled):
        for _ in steps:
            pass
    assert convert.fingerprint() == before
    assert (sc.render.engine, sc.render.use_persistent_data) == (engine, persistent)
    assert list(tmp_path.iterdir()) == []
    sc.camera = None
    with pytest.raises(core_errors.SpecGenError, match="no camera"):
        fullscene.FullSceneRenderJob(sc, None, RGB_WL).run()


# ------------------------------------------------------------------------- SpecGen scenes
@pytest.fixture(scope="module")
def white_atlas(tmp_path_factory):
    """A white SpecGen BRDF (flat 0.8 Lambert + faint GGX) baked at 21 bands."""
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.full(RGB_WL.size, 0.8 / np.pi) + ggx_lobe(wi, wo, 0.25)[:, None] * 0.04
    return bake.bake_atlas(BRDFTable.tabulate(fn, RGB_WL), tmp_path_factory.mktemp("w") / "w.exr")


def test_cornell_box_bleeds_wall_colours_onto_a_white_specgen_sphere(white_atlas):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = render.make_material("SpecGen white", white_atlas)
    sc = demo.cornell_box(mat, samples=48, size=(40, 40))
    stack = fullscene.FullSceneRenderJob(sc, None, RGB_WL).run()

    def long_over_short(offset) -> float:
        p = world_to_camera_view(sc, sc.camera, Vector((0.0, 0.1, 0.45)) + Vector(offset))
        x, y = int(p.x * 40), int((1 - p.y) * 40)
        s = stack[y - 1:y + 2, x - 1:x + 2].reshape(-1, RGB_WL.size).mean(0)
        return float(s[RGB_WL >= 620].mean() / s[RGB_WL <= 480].mean())

    red_side, green_side = long_over_short((-0.32, -0.25, 0.0)), long_over_short((0.32, -0.25, 0.0))
    assert red_side > 1.2 * green_side, (red_side, green_side)   # the sphere itself is flat white


@pytest.mark.slow
def test_batch_renders_a_blend_file_in_full_scene_mode(white_atlas, tmp_path):
    import subprocess
    import sys

    from specgen_addon.render.spectral_exr import read_spectral_exr

    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = render.make_material("SpecGen white", white_atlas)
    demo.ordinary_scene(samples=2, size=(20, 14), specgen_material=mat)
    blend = tmp_path / "ordinary.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    repo = Path(batch.__file__).resolve().parent
    done = subprocess.run([sys.executable, str(repo / "batch.py"), "--scene", str(blend), "--out",
                           str(tmp_path / "a"), "--bands", "6"], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    exr = "Scene_Camera_f0001.exr"                      # <scene>_<camera>_f<frame>.exr
    written = read_spectral_exr(tmp_path / "a" / exr)
    assert written.values.shape == (14, 20, 6)
    assert str(written.header["specgenExactDirect"]).endswith("yes")   # the lookups lit the sphere
    # as `blender --background ordinary.blend --python batch.py -- --scene --out b`
    script = ("import sys, runpy, bpy\n"
              f"bpy.ops.wm.open_mainfile(filepath={str(blend)!r})\n"
              f"sys.argv = ['blender', '--background', {str(blend)!r}, '--python', 'batch.py', "
              f"'--', '--scene', '--out', {str(tmp_path / 'b')!r}, '--bands', '4']\n"
              f"runpy.run_path({str(repo / 'batch.py')!r}, run_name='__main__')\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600, cwd=repo)
    assert done.returncode == 0, done.stderr[-2000:]
    assert read_spectral_exr(tmp_path / "b" / exr).values.shape == (14, 20, 4)
    bad = subprocess.run([sys.executable, str(repo / "batch.py"), "--scene", str(tmp_path / "no.blend"),
                          "--out", str(tmp_path / "c")], capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "no such .blend" in bad.stderr


def test_f12_after_apply_shows_the_rgb_standin_and_exact_mode_leaves_no_temp_paths(blank_scene, white_atlas):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    scene_mod.add_camera(sc)
    mat = render.make_material("SpecGen white", white_atlas)
    scene_mod.add_mesh(sc, "sphere").data.materials.append(mat)
    # not exactly behind the camera: the exact lookups, which Full Scene's direct light now uses,
    # read a few % dark within ~1° of retro-reflection (test_fullscene_fidelity, xfail)
    scene_mod.add_sun(sc, (0.2, 0.3, 0.9), irradiance=np.pi)
    scene_mod.set_world_environment(sc, None, color=(0.05, 0.05, 0.05))
    sc.render.resolution_x = sc.render.resolution_y = 16
    sc.cycles.samples = 8
    f12 = _rgb_render(sc)[..., :3]                   # F12: the native closure stack, RGB
    assert 0.7 < float(np.median(f12[4:12, 4:12])) < 1.2          # lit white, not black or white-out
    stack = fullscene.FullSceneRenderJob(sc, None, RGB_WL).run()
    assert _psnr(f12, spectra.spectral_to_linear_srgb(stack, RGB_WL)) >= 35.0  # stand-in = spectral
    render.SpectralRenderJob(sc, None, samples=1, resolution=(8, 8)).run()   # exact, with a world
    node = render.script_node(mat)
    assert node.inputs["EnvMap"].default_value == "" and node.inputs["EnvList"].default_value == ""
    out = render.material_output(mat)
    assert out.inputs["Surface"].links[0].from_node.name != render.BRDF_NODE_NAME  # stack again


def test_full_scene_refuses_a_material_whose_lookups_are_gone_before_rendering(blank_scene, tmp_path):
    """The lookups deleted and no compact file to bake them again from: the default render names
    the material and the file, as the exact render does, instead of writing the stand-in alone."""
    from blend_reopen import small_table, sphere_scene_with_material

    mat, _ = sphere_scene_with_material(tmp_path, "ball", small_table())
    gone = sorted(tmp_path.glob("ball_lookup.g*.exr"))
    for f in gone + [tmp_path / "ball.npz"]:
        f.unlink()
    out = tmp_path / "out" / "s.exr"
    out.parent.mkdir()
    renders = []

    def counted(*_):
        renders.append(1)

    bpy.app.handlers.render_pre.append(counted)
    try:
        with pytest.raises(core_errors.SpecGenError,
                           match=rf"material 'SpecGen ball': baked lookup {gone[0]} is missing"):
            fullscene.FullSceneRenderJob(bpy.context.scene, out, WL, warn=lambda _: None).run()
    finally:
        bpy.app.handlers.render_pre.remove(counted)
    assert renders == [] and not any(out.parent.iterdir())
    # without the exact lookups asked for, the closures alone render (what the user chose)
    stack = fullscene.FullSceneRenderJob(bpy.context.scene, None, WL, exact_direct=False).run()
    assert stack.shape[-1] == WL.size and stack.max() > 0


def test_a_generated_material_on_no_object_is_named_as_absent_from_the_render(blank_scene, white_atlas):
    """Generate without Apply, then render: the render says no object shows a SpecGen material,
    and says nothing of how that unused material's closures would render."""
    render.make_material("SpecGen white", white_atlas)                 # generated, not applied
    demo.ordinary_scene(samples=1, size=(12, 8))
    warnings = []
    fullscene.FullSceneRenderJob(bpy.context.scene, None, np.array([450.0, 550.0, 650.0]),
                                 warn=warnings.append).run()
    assert any("no render-visible object uses a SpecGen material" in w for w in warnings), warnings
    assert not any("SpecGen white" in w for w in warnings), warnings
