"""The Blender side, headless with the bpy module and real Cycles (no mocks).

The repository is imported as the package ``specgen`` (:func:`batch.load_package`), exactly as an
installed extension is imported as ``bl_ext.<repo>.specgen``: ``ops`` reaches the core as the
top-level package ``specgen_addon`` in both cases.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import batch  # noqa: E402
from addon_modules import PKG, addon_module, psnr as _psnr  # noqa: E402  (after the bpy skip)
bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
scene_mod = addon_module("ops.scene")
core_errors = addon_module("specgen_addon.common.errors")

from specgen_addon.render import DistantLight, Environment, EnvSampling, render_spectral, sphere_geometry  # noqa: E402
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff  # noqa: E402
from specgen_addon.brdf.table import BRDFTable  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
WL = np.array([410.0, 480.0, 540.0, 600.0, 660.0, 720.0])


class _Lobes:
    """Spectral test BRDF (sr⁻¹): coloured Lambertian + a GGX lobe with its own spectrum; with
    ``rich`` also a sharper lobe, a grazing (Schlick-like) and a retro-reflective term with three
    more spectra, so the spectra span five dimensions and need two groups of four basis coefficients."""

    def __init__(self, rich: bool = False):
        self.rich = rich
        self.rho = np.interp(WL, [400, 550, 720], [0.15, 0.7, 0.35])
        self.spec = np.interp(WL, [400, 720], [0.9, 0.2])
        self.spec2 = np.interp(WL, [400, 600, 720], [0.1, 0.8, 0.3])
        self.graze = np.interp(WL, [400, 500, 720], [0.6, 0.05, 0.5])
        self.back = np.interp(WL, [400, 650, 720], [0.05, 0.5, 0.1])

    @staticmethod
    def _ggx(wi, wo, alpha):
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        a2 = alpha ** 2
        cos_h = np.clip(h[:, 2], 0.0, 1.0)
        d = a2 / (np.pi * (cos_h ** 2 * (a2 - 1) + 1) ** 2)
        return d / (4 * np.clip(wi[:, 2], 1e-3, None) * np.clip(wo[:, 2], 1e-3, None)), h

    def eval(self, wi, wo, wavelengths_nm=None):
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        lobe, h = self._ggx(wi, wo, 0.25)
        f = self.rho[None] / np.pi + 0.1 * lobe[:, None] * self.spec[None]
        if self.rich:
            sharp, _ = self._ggx(wi, wo, 0.08)
            cos_d = np.clip(np.sum(wi * h, -1), 0.0, 1.0)
            f = f + 0.02 * sharp[:, None] * self.spec2[None] + 0.3 * ((1 - cos_d) ** 5)[:, None] * self.graze[None]
            back = np.clip(np.sum(wi * wo, -1), 0.0, 1.0) ** 4  # retro-reflection
            f = f + 0.2 * back[:, None] * self.back[None]
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        return np.where(above[:, None], f, 0.0)


def _tabulate(brdf) -> BRDFTable:
    return BRDFTable.tabulate(lambda th, td, pd: brdf.eval(*io_from_half_diff(th, td, pd)), WL)


@pytest.fixture(scope="module")
def table() -> BRDFTable:
    """Two spectral components: the basis needs one group of four coefficients (one render)."""
    return _tabulate(_Lobes())


@pytest.fixture(scope="module")
def rich_table() -> BRDFTable:
    """Five spectral components: two groups (two Cycles renders)."""
    return _tabulate(_Lobes(rich=True))


def _sphere_scene(atlas, resolution_filter: float = 0.01):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    obj = scene_mod.add_mesh(sc, "sphere")
    obj.data.materials.append(render.make_material("SpecGen test", atlas))
    sc.cycles.filter_width = resolution_filter  # sample pixel centres, as the reference does
    return sc


# ------------------------------------------------------------------------- register / compile
def test_register_unregister_leaves_nothing_behind(blank_scene):
    before_types = set(dir(bpy.types))
    before_ops = set(dir(bpy.ops.specgen)) if hasattr(bpy.ops, "specgen") else set()
    PKG.register()
    try:
        assert hasattr(bpy.types.Scene, "specgen")
        assert {"SPECGEN_PT_main", "SPECGEN_OT_generate_brdf", "SPECGEN_OT_apply",
                "SPECGEN_OT_render_stack"} <= set(dir(bpy.types))
        assert bpy.types.SPECGEN_PT_main.bl_category == "SpecGen"
        assert bpy.context.scene.specgen.bands == 21
    finally:
        PKG.unregister()
    assert set(dir(bpy.types)) == before_types
    assert not hasattr(bpy.types.Scene, "specgen")
    assert bpy.types.PropertyGroup.bl_rna_get_subclass_py("SpecGenSettings") is None
    assert (set(dir(bpy.ops.specgen)) if hasattr(bpy.ops, "specgen") else set()) <= before_ops
    PKG.register()  # and it can come back
    PKG.unregister()


def test_osl_shader_compiles_with_expected_sockets(blank_scene):
    mat = bpy.data.materials.new("osl")
    node = mat.node_tree.nodes.new("ShaderNodeScript")
    render.compile_script_node(node)
    inputs = {s.name: s.type for s in node.inputs}
    assert inputs["Atlas"] == "STRING" and inputs["EnvMap"] == "STRING" and inputs["EnvList"] == "STRING"
    assert inputs["TilesX"] == "INT" and inputs["PhiD"] == "INT" and inputs["EnvSamples"] == "INT"
    for i in range(bake.MAX_LIGHTS):
        assert inputs[f"Light{i}Kind"] == "INT"
        assert inputs[f"Light{i}Vec"] == "VECTOR"
        assert inputs[f"Light{i}Color"] == "RGBA"
    assert [s.name for s in node.outputs] == ["BSDF"] and node.outputs[0].type == "SHADER"


def test_broken_shader_source_is_reported(monkeypatch, tmp_path):
    bad = tmp_path / "bad.osl"
    bad.write_text(render.SHADER_PATH.read_text().replace("float th, td, pd, x, y, tk;", "float v;", 1))
    monkeypatch.setattr(render, "SHADER_PATH", bad)
    monkeypatch.setattr(render, "SHADER_TEXT_NAME", "bad.osl")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    node = bpy.data.materials.new("osl").node_tree.nodes.new("ShaderNodeScript")
    with pytest.raises(core_errors.SpecGenError, match="did not compile"):
        render.compile_script_node(node)


# ------------------------------------------------------------------------- Cycles vs reference
@pytest.mark.slow
def test_cycles_sphere_matches_reference_under_a_sun(rich_table, tmp_path):
    table = rich_table
    info = bake.bake_atlas(table, tmp_path / "a.exr", tolerance=1e-6)  # 6 coefficients: 2 renders
    assert info.n_renders == 2
    sc = _sphere_scene(info)
    direction = (0.35, 0.45, 0.82)
    scene_mod.add_sun(sc, direction, irradiance=np.pi)
    job = render.SpectralRenderJob(sc, None, samples=2, resolution=(64, 64))
    got = job.run()
    ref = render_spectral(table, sphere_geometry(64), lights=[DistantLight(direction, np.pi)],
                          wavelengths_nm=WL).spectral
    assert got.shape == ref.shape == (64, 64, WL.size)
    psnr = [_psnr(got[..., b], ref[..., b]) for b in range(WL.size)]
    assert min(psnr) >= 40.0, psnr


@pytest.mark.slow
def test_cycles_sphere_matches_reference_under_an_environment_map(table, tmp_path):
    from specgen_addon.render.environment_maps import env_path

    env = Environment.from_file(env_path("forest"), max_width=8)  # the reference's texels …
    env_file = tmp_path / "env.exr"
    batch._write_rgb_exr(env_file, env.rgb)                     # … are what Cycles' world shows
    info = bake.bake_atlas(table, tmp_path / "a.exr")
    assert info.n_renders == 1 and info.rel_error < 1e-4         # rank 2: one render, exact
    sc = _sphere_scene(info)
    scene_mod.set_world_environment(sc, env_file, 1.0)
    job = render.SpectralRenderJob(sc, None, samples=128, resolution=(40, 40), env_samples=8,
                                   env_lobe=8.0)
    got = job.run()
    # Plain MIS without the reference's control variate: on a map this coarse the control
    # variate is off by a few per cent at single pixels (checked against a dense quadrature).
    sampling = dataclasses.replace(EnvSampling(), control_variate=False).scaled(8)
    ref = render_spectral(table, sphere_geometry(40), environment=env, wavelengths_nm=WL,
                          sampling=sampling).spectral
    psnr = [_psnr(got[..., b], ref[..., b]) for b in range(WL.size)]
    assert min(psnr) >= 35.0, psnr


# ------------------------------------------------------------------------- outputs
def test_spectral_exr_and_preview_are_written_and_cancel_writes_nothing(table, tmp_path):
    from specgen_addon.render.spectral_exr import read_spectral_exr

    info = bake.bake_atlas(table, tmp_path / "lookup" / "a.exr")
    sc = _sphere_scene(info)
    scene_mod.add_sun(sc, (0.0, 0.0, 1.0), irradiance=np.pi)
    out = tmp_path / "out"
    out.mkdir()

    job = render.SpectralRenderJob(sc, out / "stack.exr", samples=1, resolution=(16, 16))
    steps = job.steps()
    next(steps)                      # lighting baked, first render not started yet
    job.cancel()
    with pytest.raises(core_errors.Cancelled):
        for _ in steps:
            pass
    assert list(out.iterdir()) == []

    job = render.SpectralRenderJob(sc, out / "stack.exr", samples=1, resolution=(16, 16))
    stack = job.run()
    written = read_spectral_exr(out / "stack.exr")
    np.testing.assert_allclose(written.wavelengths_nm, WL)
    np.testing.assert_array_equal(written.values, stack)
    assert (out / "stack_preview.png").is_file()
    with pytest.raises(core_errors.OutputExistsError):
        render.SpectralRenderJob(sc, out / "stack.exr", samples=1, resolution=(16, 16)).run()
    assert sorted(p.name for p in out.iterdir()) == ["stack.exr", "stack_preview.png"]


def test_scene_is_restored_after_a_spectral_render(table, tmp_path):
    info = bake.bake_atlas(table, tmp_path / "a.exr")
    sc = _sphere_scene(info)
    sun = scene_mod.add_sun(sc, (0.0, 0.0, 1.0))
    world = scene_mod.set_world_environment(sc, None, color=(0.2, 0.2, 0.2))
    sc.render.engine = "BLENDER_EEVEE" if "BLENDER_EEVEE" in {e.identifier for e in
                                                             sc.render.bl_rna.properties["engine"].enum_items} else sc.render.engine
    engine, samples, groups = sc.render.engine, sc.cycles.samples, len(bpy.data.node_groups)
    render.SpectralRenderJob(sc, None, samples=1, resolution=(8, 8)).run()
    assert sc.render.engine == engine and sc.cycles.samples == samples
    assert sc.world == world and not sun.hide_render
    assert len(bpy.data.node_groups) == groups and "SpecGen black" not in bpy.data.worlds


# ------------------------------------------------------------------------- packaging / CLI
@pytest.mark.slow
def test_extension_zip_installs_and_registers(tmp_path):
    zip_path = tmp_path / "specgen.zip"
    subprocess.run([sys.executable, str(REPO / "scripts" / "build_extension.py"), "--no-wheels",
                    "--out", str(zip_path)], check=True, capture_output=True)
    script = (
        "import sys, bpy\n"
        f"r = bpy.ops.extensions.package_install_files(filepath={str(zip_path)!r}, repo='user_default', "
        "enable_on_install=True)\n"
        "assert r == {'FINISHED'}, r\n"
        "import bl_ext.user_default.specgen as ext\n"
        "assert 'bl_ext.user_default.specgen.ops.render' not in sys.modules or True\n"
        "assert hasattr(bpy.types, 'SPECGEN_PT_main') and hasattr(bpy.types.Scene, 'specgen')\n"
        "from specgen_addon.bake import lookup as bake\n"
        "assert bake.__file__.startswith(ext.__file__.rsplit('__init__', 1)[0]), bake.__file__\n"
        "from bl_ext.user_default.specgen.ops import reporting\n"
        "from specgen_addon.common import errors\n"
        "from specgen_addon.cli.app import run_guarded\n"
        "assert reporting.Cancelled is errors.Cancelled  # one core for the extension and the CLI\n"
        "def work():\n"
        "    raise reporting.Cancelled('stopped in the extension')\n"
        "print('SPECGEN-GUARD', run_guarded('the test', work))\n"
        "print('SPECGEN-INSTALLED', ext.__file__)\n")
    env = {**os.environ, "HOME": str(tmp_path / "home")}
    (tmp_path / "home").mkdir()
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                          timeout=240, cwd=tmp_path)
    assert "SPECGEN-INSTALLED" in done.stdout, done.stdout[-2000:] + done.stderr[-2000:]
    assert str(tmp_path / "home") in done.stdout
    assert "SPECGEN-GUARD 2" in done.stdout and "error: stopped in the extension" in done.stderr


@pytest.mark.parametrize("case", ["missing", "no_sphere", "unknown_env", "unwritable"])
def test_batch_bad_input_exits_nonzero_with_one_line(case, tmp_path, sphere_photo):
    from PIL import Image

    flat = tmp_path / "flat.png"
    Image.fromarray(np.full((64, 64, 3), 128, np.uint8)).save(flat)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    args = {"missing": ["--image", str(tmp_path / "nope.png"), "--out", str(tmp_path / "o")],
            "no_sphere": ["--image", str(flat), "--out", str(tmp_path / "o")],
            "unknown_env": ["--image", str(flat), "--env", "moon", "--out", str(tmp_path / "o")],
            "unwritable": ["--image", str(flat), "--out", str(blocker / "sub")]}[case]
    if case in ("unknown_env", "unwritable"):  # needs a sphere to get past the image check
        args[1] = str(sphere_photo)
    done = subprocess.run([sys.executable, str(REPO / "batch.py"), *args], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = [l for l in done.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("batch.py: error:"), done.stderr
    expected = {"missing": "not found", "no_sphere": "no sphere", "unknown_env": "moon",
                "unwritable": "output folder"}[case]
    assert expected in lines[0]


def test_batch_help_lists_the_arguments():
    done = subprocess.run([sys.executable, str(REPO / "batch.py"), "--help"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0
    for flag in ("--image", "--mesh", "--env", "--out", "--bands", "--samples", "--resolution",
                 "--overwrite"):
        assert flag in done.stdout


def test_panel_draws_every_setting_and_the_three_buttons():
    import importlib.util

    spec = importlib.util.spec_from_file_location("draw_panel", REPO / "scripts" / "draw_panel.py")
    draw_panel = importlib.util.module_from_spec(spec)
    sys.modules["draw_panel"] = draw_panel  # dataclasses look their module up
    spec.loader.exec_module(draw_panel)
    PKG.register()
    try:
        rows = draw_panel.record_panel(bpy.context)
        s = bpy.context.scene.specgen
        assert s.render_mode == "FULL_SCENE"                 # the default: the whole scene
        s.render_mode = "EXACT"
        exact_rows = draw_panel.record_panel(bpy.context)
        s.running = "Rendering spectral stack"
        busy = draw_panel.record_panel(bpy.context)
    finally:
        PKG.unregister()
    props = {r.name for r in rows if r.kind in ("prop", "template")}
    assert {"image", "image_path", "weights_path", "wl_min", "wl_max", "bands", "lookup_resolution",
            "render_mode", "output_dir", "overwrite", "export_table", "material"} <= props
    # full-scene: the scene's own resolution, samples and denoising, editable in the panel
    assert {"resolution_x", "resolution_y", "resolution_percentage", "samples", "use_denoising",
            "quick_preview", "overwrite_outputs"} <= props
    assert "env_samples" not in props
    assert {"samples", "resolution", "env_samples"} <= {r.name for r in exact_rows if r.kind == "prop"}
    assert "resolution_x" not in {r.name for r in exact_rows if r.kind == "prop"}
    buttons = [r.name for r in rows if r.kind == "operator"]
    assert buttons == ["specgen.generate_brdf", "specgen.apply", "specgen.render_stack",
                       "specgen.estimate_time"]
    assert all(r.enabled for r in rows if r.kind == "operator")
    # while a job runs the buttons are disabled and a progress bar is shown
    assert not any(r.enabled for r in busy if r.kind == "operator")
    assert any(r.kind == "progress" for r in busy)


def test_operators_apply_and_render_headless_and_report_errors(table, tmp_path, registered_addon):
    info = bake.bake_atlas(table, tmp_path / "lookup" / "brdf_lookup.exr")
    bake.save_atlas_info(info, tmp_path / "lookup" / "brdf_lookup.json")
    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    obj = scene_mod.add_mesh(sc, "sphere")
    scene_mod.add_sun(sc, (0.0, 0.0, 1.0))
    s = sc.specgen
    s.output_dir = str(tmp_path / "out")
    s.resolution, s.samples = 16, 1
    s.render_mode = "EXACT"
    with pytest.raises(RuntimeError, match="no render-visible object uses a SpecGen material"):
        bpy.ops.specgen.render_stack()          # reported through self.report, one line
    assert not bpy.ops.specgen.apply.poll()     # nothing generated yet
    s.atlas_json = str(tmp_path / "lookup" / "brdf_lookup.json")
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    assert bpy.ops.specgen.apply() == {"FINISHED"}
    assert render.is_specgen_material(obj.active_material)
    assert bpy.ops.specgen.render_stack() == {"FINISHED"}
    # named after the scene, the camera and the frame
    assert (tmp_path / "out" / f"{sc.name}_SpecGen_camera_f{sc.frame_current:04d}.exr").is_file()
    with pytest.raises(RuntimeError, match="already exists"):
        bpy.ops.specgen.render_stack()          # never overwritten unless asked
    s.overwrite_outputs = True                   # outputs only; materials keep their switch
    assert not s.overwrite
    assert bpy.ops.specgen.render_stack() == {"FINISHED"}
    s.render_mode = "FULL_SCENE"                 # the scene's resolution and samples
    sc.render.resolution_x, sc.render.resolution_y, sc.cycles.samples = 12, 8, 1
    assert bpy.ops.specgen.render_stack(filename="full.exr") == {"FINISHED"}
    from specgen_addon.render.spectral_exr import read_spectral_exr

    assert read_spectral_exr(tmp_path / "out" / "full.exr").values.shape == (8, 12, s.bands)
    assert "specgen_fit_error" in obj.active_material


def test_generate_operator_bakes_a_lookup_from_an_image(tmp_path, registered_addon, sphere_photo,
                                                        default_weights):
    s = bpy.context.scene.specgen
    s.image_path = str(sphere_photo)
    s.output_dir = str(tmp_path / "out")
    s.bands = 6
    assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
    info = bake.load_atlas_info(s.atlas_json)
    assert info.wavelengths_nm.size == 6 and all(p.is_file() for p in info.group_paths)


@pytest.mark.slow
def test_batch_renders_a_table_on_an_obj_mesh_into_a_readable_spectral_exr(table, tmp_path):
    colour = pytest.importorskip("colour")
    table.save(tmp_path / "brdf.npz")
    cube = tmp_path / "cube.obj"
    verts = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    cube.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in verts) +
                    "".join("f " + " ".join(map(str, f)) + "\n" for f in faces))
    done = subprocess.run([sys.executable, str(REPO / "batch.py"), "--brdf", str(tmp_path / "brdf.npz"),
                           "--mesh", str(cube), "--env", "studio", "--sun", "--out", str(tmp_path / "out"),
                           "--bands", "5", "--wl-min", "420", "--wl-max", "700", "--resolution", "32",
                           "--samples", "4"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    exr = tmp_path / "out" / "brdf_cube_studio.exr"
    components = colour.read_spectral_image_Fichet2021(exr)
    wavelengths, values = components["S0"]
    np.testing.assert_allclose(wavelengths, np.linspace(420, 700, 5))
    assert values.shape == (32, 32, 5) and np.all(np.isfinite(values))
    assert values[16, 16].min() > 0 and values[0, 0].max() == 0  # the cube in the middle, black corner
    assert (tmp_path / "out" / "brdf_cube_studio_preview.png").is_file()
