"""The exact shader's lookup is the table's own trilinear interpolation, also beside a sharp peak.

The lookup atlas packs one 90×90 (θh × θd) tile per φd sample side by side, so a tile's last θh
column (θh ≈ 90°) touches the next tile's first one (θh = 0, the specular peak). A lookup filter
wider than bilinear (OSL's default, a bicubic B-spline) reaches across that border and across the
peak: a mirror-like table then renders too bright at grazing light and on its highlight (+6 % on
RGL `ilm_solo_m_68`). Truth: the NumPy reference renderer on the same sphere and sun.
"""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.bake.closure_fit import ggx_lobe
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([450.0, 550.0, 650.0])
SUN = (0.35, 0.45, 0.82)
RES = 48


def _mirror_like(th, td, pd):
    """A dim grey body under a very sharp, very tall GGX peak (α = 0.0025): most of the peak's
    table entries sit in the first few θh columns of each tile."""
    wi, wo = io_from_half_diff(th, td, pd)
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    return above * (0.02 / np.pi + ggx_lobe(wi, wo, 0.05)[:, None] * np.array([0.5, 0.4, 0.3]))


def _render(table: BRDFTable, tmp_path, sun) -> tuple[np.ndarray, np.ndarray]:
    pytest.importorskip("bpy")
    from addon_modules import addon_module

    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry

    bake = addon_module("specgen_addon.bake.lookup")
    render = addon_module("ops.render")
    scene_mod = addon_module("ops.scene")
    info = bake.bake_atlas(table, tmp_path / "t.exr", tolerance=0.0)
    sc, _ = scene_mod.new_reference_sphere_scene(lambda: render.make_material("SpecGen mirror", info), sun)
    got = render.SpectralRenderJob(sc, None, samples=1, resolution=(RES, RES)).run()
    ref = render_spectral(table, sphere_geometry(RES), lights=[DistantLight(sun, np.pi)],
                          wavelengths_nm=WL).spectral
    return ref, got


@pytest.mark.blender
def test_a_mirror_like_table_renders_its_highlight_and_body_as_the_table_says(tmp_path):
    ref, got = _render(BRDFTable.tabulate(_mirror_like, WL), tmp_path, SUN)
    r, g = ref.sum(-1), got.sum(-1)
    lit = r > 0
    body = lit & (r < np.percentile(r[lit], 99))    # leave the one-pixel highlight aside
    # every body pixel as the table says (a bleed from the peak tile gives 10⁴× at grazing light)
    assert np.all(np.abs(g[body] - r[body]) <= 0.01 * r[body] + 1e-4 * r[lit].max()), \
        np.max(np.abs(g[body] - r[body]) / np.maximum(r[body], 1e-9))
    # and the highlight: a bicubic lookup spreads the peak over its neighbours (+7.5 % here)
    assert g[lit].sum() / r[lit].sum() == pytest.approx(1.0, abs=0.01)


@pytest.mark.blender
def test_a_material_compiled_by_an_older_version_renders_with_this_versions_shader(tmp_path, monkeypatch):
    bpy = pytest.importorskip("bpy")
    from addon_modules import addon_module

    bake = addon_module("specgen_addon.bake.lookup")
    render = addon_module("ops.render")
    scene_mod = addon_module("ops.scene")
    info = bake.bake_atlas(BRDFTable.tabulate(_mirror_like, WL), tmp_path / "t.exr")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    mat = render.make_material("SpecGen old", info)
    scene_mod.add_mesh(sc, "sphere").data.materials.append(mat)
    node = render.script_node(mat)
    atlas = node.inputs["Atlas"].default_value
    # as a .blend saved by an older SpecGen: its own OSL text and bytecode, no source digest
    shipped = render.SHADER_PATH
    older = tmp_path / "older.osl"
    older.write_text(shipped.read_text().replace('"interp", "linear"', '"interp", "bilinear"'))
    monkeypatch.setattr(render, "SHADER_PATH", older)
    render.compile_script_node(node)
    monkeypatch.setattr(render, "SHADER_PATH", shipped)
    del node[render.SHADER_DIGEST_KEY]
    assert '"bilinear"' in node.bytecode
    render.SpectralRenderJob(sc, None)._preflight()
    assert '"bilinear"' not in node.bytecode and '"linear"' in node.bytecode
    assert node.inputs["Atlas"].default_value == atlas           # its lookups kept
