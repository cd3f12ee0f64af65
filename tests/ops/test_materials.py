"""Several SpecGen materials in one scene: named datablock sets, Overwrite, Apply, and a render of
two materials with different spectral bases side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import PKG, addon_module  # noqa: E402  (after the bpy skip)
bake = addon_module("specgen_addon.bake.lookup")
naming = addon_module("ops.naming")
render = addon_module("ops.render")
scene_mod = addon_module("ops.scene")
travel = addon_module("ops.travel")

from specgen_addon.brdf.rusinkiewicz import io_from_half_diff  # noqa: E402
from specgen_addon.brdf.table import BRDFTable  # noqa: E402
from specgen_addon.generate.pipeline import generate  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
WL = np.array([420.0, 480.0, 540.0, 600.0, 660.0])
RHO = {"red": np.array([0.05, 0.08, 0.15, 0.7, 0.8]), "blue": np.array([0.7, 0.6, 0.2, 0.08, 0.05])}


def _lambertian(rho: np.ndarray) -> BRDFTable:
    def f(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        return np.where(above[:, None], rho[None] / np.pi, 0.0)

    return BRDFTable.tabulate(f, WL)


def _record_panel():
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("draw_panel", REPO / "scripts" / "draw_panel.py")
    draw_panel = importlib.util.module_from_spec(spec)
    sys.modules["draw_panel"] = draw_panel  # dataclasses look their module up
    spec.loader.exec_module(draw_panel)
    return draw_panel.record_panel(bpy.context)


def test_generate_names_never_collide_unless_overwrite(tmp_path):
    assert naming.clean_stem("my photo (2).png") == "my_photo_2"
    assert naming.stem_for_generate("sphere.png", tmp_path, False, []) == "sphere"
    (tmp_path / "sphere_lookup.json").write_text("{}")
    assert naming.stem_for_generate("sphere.png", tmp_path, False, []) == "sphere.001"
    assert naming.stem_for_generate("sphere.png", tmp_path, False, ["SpecGen sphere.001"]) == "sphere.002"
    assert naming.stem_for_generate("sphere.png", tmp_path, True, ["SpecGen sphere"], owned=lambda s: True) == "sphere"
    # a node group of the set's name (e.g. the user's copy of it) also makes a new stem
    assert naming.stem_for_generate("sphere.png", tmp_path, False, [], ["SpecGen sphere.001"]) == "sphere.002"
    assert naming.group_name("sphere.001") == naming.material_name("sphere.001")


def test_replace_materials_reuses_a_stem_only_for_this_blends_own_set(tmp_path):
    """Two .blend files beside each other share //specgen/: Replace Materials replaces the set its
    own material names, and never another file's set of the same stem."""
    (tmp_path / "sphere_lookup.json").write_text("{}")            # a set in the folder
    assert naming.stem_for_generate("sphere.png", tmp_path, True, [], owned=lambda s: s == "sphere") == "sphere"
    assert naming.stem_for_generate("sphere.png", tmp_path, True, ["SpecGen sphere"]) == "sphere.001"
    assert naming.stem_for_generate("ball.png", tmp_path, True, []) == "ball"   # nothing there yet


def test_a_set_is_this_blends_own_when_its_material_here_names_its_lookups(blank_scene, tmp_path):
    mine, theirs = tmp_path / "specgen", tmp_path / "elsewhere"
    mat = bpy.data.materials.new(naming.material_name("sphere"))
    mat["specgen_atlas"] = str(mine / "sphere_lookup.exr")
    assert travel.owns_set(str(mine), "sphere")
    assert not travel.owns_set(str(theirs), "sphere")              # the same stem in another folder
    assert not travel.owns_set(str(mine), "sphere.001")            # no material of that stem here


def test_stems_are_safe_on_windows_and_macos(tmp_path):
    assert naming.clean_stem("Kugel Öl.png") == "Kugel_Ol"
    assert naming.clean_stem("ça_va.jpg") == "ca_va"
    assert naming.clean_stem("con.png") == "con_" and naming.clean_stem("COM1.exr") == "COM1_"
    assert naming.clean_stem("console.png") == "console"
    (tmp_path / "sphere.npz").write_bytes(b"")
    # one file on a case-insensitive system: Sphere.png does not take sphere's files
    assert naming.files_of(tmp_path, "Sphere") == [tmp_path / "sphere.npz"]
    assert naming.stem_for_generate("Sphere.PNG", tmp_path, False, []) == "Sphere.001"
    assert naming.stem_for_generate("Sphere.PNG", tmp_path, False, ["SpecGen sphere.001"]) == "Sphere.002"


def _group_of(mat):
    node = mat.node_tree.nodes[render.BRDF_NODE_NAME]
    assert node.type == "GROUP" and render.script_node(mat).id_data == node.node_tree
    return node.node_tree


def test_two_generates_make_two_material_sets_and_apply_assigns_the_chosen_one(tmp_path, default_weights):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    PKG.register()
    try:
        sc = bpy.context.scene
        a = scene_mod.add_mesh(sc, "sphere")
        b = scene_mod.add_mesh(sc, "suzanne")
        s = sc.specgen
        s.image_path = str(REPO / "examples" / "sphere.png")
        s.output_dir = str(tmp_path)
        s.bands, s.lookup_resolution = 4, "45"
        assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
        first = s.material
        assert first.name == "SpecGen sphere" and first["specgen_preview"] in bpy.data.images
        assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}       # Overwrite off: a new set
        second = s.material
        assert second.name == "SpecGen sphere.001" and second != first
        assert (tmp_path / "sphere_lookup.json").is_file() and (tmp_path / "sphere.001_lookup.json").is_file()
        compact = sorted(tmp_path.glob("*.npz"))                      # the compact material of each
        assert [q.name for q in compact] == ["sphere.001.npz", "sphere.npz"]
        assert all(q.stat().st_size <= 10 * 2**20 for q in compact)
        assert first["specgen_atlas_groups"][0] != second["specgen_atlas_groups"][0]
        groups = {m.name: _group_of(m) for m in (first, second)}       # one node group per set
        assert [g.name for g in groups.values()] == ["SpecGen sphere", "SpecGen sphere.001"]
        for mat, group in zip((first, second), groups.values()):
            assert group.users == 1                                   # used by its material only
            assert render.script_node(mat).inputs["Atlas"].default_value == mat["specgen_atlas_groups"][0]
        for obj, mat in ((a, first), (b, second)):
            s.material = mat
            bpy.ops.object.select_all(action="DESELECT")
            obj.select_set(True)
            bpy.context.view_layer.objects.active = obj
            assert bpy.ops.specgen.apply() == {"FINISHED"}
        assert a.active_material == first and b.active_material == second
        s.refine_residual = 36.54                                     # filled by a refinement (dB)
        rows = _record_panel()
        labels = [r.label for r in rows if r.kind == "label"]
        assert "Refined photo match: 36.5 dB" in labels and "SpecGen sphere" in labels
        assert any(r.kind == "template" and r.value == "SpecGen sphere.001" for r in rows)
        user = bpy.data.materials.new("user's mix")                   # the group used elsewhere
        user_node = user.node_tree.nodes.new("ShaderNodeGroup")
        user_node.node_tree = groups["SpecGen sphere"]
        user.node_tree.links.new(user_node.outputs["BSDF"], render.material_output(user).inputs["Surface"])
        s.overwrite = True                                            # Overwrite on: same names
        s.material = first
        assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
        assert s.material.name == "SpecGen sphere" and len([m for m in bpy.data.materials if m.get("specgen")]) == 2
        assert s.material == first and _group_of(first) == groups["SpecGen sphere"]   # reused, in place
        assert len([g for g in bpy.data.node_groups if g.get("specgen")]) == 2
        assert groups["SpecGen sphere"].users == 2 and _group_of(second) == groups["SpecGen sphere.001"]
        assert render.material_output(user).inputs["Surface"].links[0].from_node == user_node  # still linked
        assert not render.is_specgen_material(user)
        bpy.data.materials.remove(user)
        # deleting a material leaves its node group unused: Blender's orphan purge removes it
        b.data.materials.clear()
        bpy.data.materials.remove(second)
        assert groups["SpecGen sphere.001"].users == 0
        bpy.data.orphans_purge(do_recursive=True)
        assert [g.name for g in bpy.data.node_groups if g.get("specgen")] == ["SpecGen sphere"]
        # another .blend writing into the same folder, Overwrite on: this file's sets are not its own
        theirs = {q.name: q.read_bytes() for q in tmp_path.glob("sphere*")}
        other = bpy.data.scenes.new("another file's")
        bpy.context.window.scene = other
        o = other.specgen
        o.image_path, o.output_dir, o.bands, o.lookup_resolution = s.image_path, str(tmp_path), 4, "45"
        o.overwrite = True
        bpy.data.materials["SpecGen sphere"].name = "the first file's, renamed"   # as if not in this file
        assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
        assert o.material.name == "SpecGen sphere.002"                          # a new set beside them
        assert {q.name: q.read_bytes() for q in tmp_path.glob("sphere*") if q.name in theirs} == theirs
        bpy.context.window.scene = sc
    finally:
        PKG.unregister()
    # unregistering the add-on keeps the user's data (materials and their groups) intact
    assert render.is_specgen_material(first) and _group_of(first).users == 1


@pytest.mark.slow
def test_two_materials_with_different_bases_render_side_by_side_keeping_their_colours(blank_scene, tmp_path):
    sc = bpy.context.scene
    scene_mod.add_camera(sc, scale=4.4)
    mats = {}
    for name, x in (("red", -1.1), ("blue", 1.1)):
        info = bake.bake_atlas(_lambertian(RHO[name]), tmp_path / f"{name}.exr")
        mats[name] = render.make_material(f"SpecGen {name}", info)
        obj = scene_mod.uv_sphere(f"sphere {name}", segments=64, rings=32)
        obj.location = (x, 0.0, 0.0)
        sc.collection.objects.link(obj)
        obj.data.materials.append(mats[name])
    assert mats["red"]["specgen_basis"] != mats["blue"]["specgen_basis"]
    light = np.array([0.3, 0.4, 0.866])
    light /= np.linalg.norm(light)
    scene_mod.add_sun(sc, tuple(light), irradiance=np.pi)
    sc.cycles.filter_width = 0.01                                       # sample pixel centres
    job = render.SpectralRenderJob(sc, tmp_path / "two.exr", samples=4, resolution=(44, 44))
    stack = job.run()
    assert len(job.groups) == 2                                         # one render per basis
    white = render._uplift(WL).sum(axis=0) * np.pi                     # E(λ) of the white sun
    for name, cx, col in (("red", -1.1, 11), ("blue", 1.1, 33)):
        x, y = -2.2 + (col + 0.5) * 0.1 - cx, 2.2 - (22 + 0.5) * 0.1     # pixel centre on the sphere
        normal = np.array([x, y, np.sqrt(1 - x * x - y * y)])           # reference frame, z to camera
        expected = RHO[name] / np.pi * white * float(normal @ light)    # Lambert: ρ/π · E · cos θi
        np.testing.assert_allclose(stack[22, col], expected, rtol=0.02)
        shape = stack[22, col] / stack[22, col].sum()                   # its own colour, tightly
        np.testing.assert_allclose(shape, expected / expected.sum(), rtol=2e-3)
    assert stack[2, 22].max() == 0                                      # gap between them: black
    # the materials show their own lookups again afterwards
    for mat in mats.values():
        node = render.script_node(mat)
        assert node.id_data == bpy.data.node_groups[mat.name]            # in the material's own group
        assert node.inputs["Atlas"].default_value == mat["specgen_atlas_groups"][0]


def test_cancelled_generate_leaves_no_files_of_its_set(tmp_path, default_weights):
    Cancelled = addon_module("specgen_addon.common.errors").Cancelled
    (tmp_path / "other_lookup.json").write_text("{}")                  # someone else's file stays
    seen = []
    with pytest.raises(Cancelled):
        generate(str(REPO / "examples" / "sphere.png"), out_dir=tmp_path, wavelengths_nm=WL[:3], n_phi_d=45,
                 backend=None, name="sphere", preview=True, progress=seen.append,
                 cancel=lambda: bool(seen) and seen[-1] >= 0.8)   # stop in the bake
    assert max(seen) >= 0.8
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other_lookup.json"]
