"""A SpecGen material travels with its .blend (headless, bpy module).

Generate in an unsaved file puts the lookups in a temporary folder; the first save moves them into
``specgen/`` beside the .blend and stores relative (``//``) paths. The .blend moved with that
folder, opened in a new process, renders the same spectral stack; with a lookup missing, the
load and the render name the material and the file."""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
scene_mod = addon_module("ops.scene")
properties = addon_module("ops.properties")
travel = addon_module("ops.travel")

from blend_reopen import reopen_and_render as _reopen
from blend_reopen import small_table as _table


@pytest.mark.slow
@pytest.mark.blender
def test_lookups_move_beside_the_saved_blend_and_a_moved_blend_renders_the_same(tmp_path, monkeypatch,
                                                                               registered_addon):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "temp"))
    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    obj = scene_mod.add_mesh(sc, "sphere")
    scene_mod.add_sun(sc, (0.0, 0.3, 1.0))
    unsaved = Path(properties.output_dir(sc.specgen))            # the unsaved file's folder
    assert str(unsaved).startswith(str(tmp_path / "temp"))
    unsaved.mkdir(parents=True)
    info = bake.bake_atlas(_table(), unsaved / "ball_lookup.exr")
    bake.save_atlas_info(info, unsaved / "ball_lookup.json")
    _table().save(unsaved / "ball.npz", compact=True)            # what Generate writes beside them
    mat = render.make_material("SpecGen ball", info)
    obj.data.materials.append(mat)
    before = render.SpectralRenderJob(sc, None, samples=1, resolution=(16, 16)).run()

    blend = tmp_path / "project" / "scene.blend"
    blend.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    moved = sorted(p.name for p in (blend.parent / "specgen").iterdir())
    assert "ball_lookup.json" in moved and any(n.startswith("ball_lookup.g") for n in moved)
    assert not any(unsaved.iterdir())                             # moved, not copied
    stored = list(bpy.data.materials["SpecGen ball"]["specgen_atlas_groups"])
    assert all(p.startswith("//specgen/ball_lookup.g") for p in stored), stored

    elsewhere = tmp_path / "elsewhere" / "project moved ü"              # spaces and non-ASCII
    elsewhere.parent.mkdir()
    shutil.move(str(blend.parent), str(elsewhere))
    out = _reopen(elsewhere / "scene.blend", tmp_path / "after.npy")
    assert "RENDERED" in out, out
    np.testing.assert_allclose(np.load(tmp_path / "after.npy"), before, rtol=1e-5, atol=1e-7)

    gone = next((elsewhere / "specgen").glob("ball_lookup.g*.exr"))
    gone.unlink()                                                      # rebuilt from the compact file
    out = _reopen(elsewhere / "scene.blend", tmp_path / "rebuilt.npy")
    assert "were missing and were baked again from" in out and "RENDERED" in out, out
    rebuilt = np.load(tmp_path / "rebuilt.npy")
    assert 10 * np.log10(before.max() ** 2 / np.mean((rebuilt - before) ** 2)) >= 60.0

    gone.unlink()
    (elsewhere / "specgen" / "ball.npz").unlink()                      # nothing to rebuild from
    out = _reopen(elsewhere / "scene.blend", tmp_path / "never.npy")
    assert f"material 'SpecGen ball': baked lookup {gone} is missing" in out, out
    assert "REFUSED" in out and not (tmp_path / "never.npy").exists()
    assert json.loads((elsewhere / "specgen" / "ball_lookup.json").read_text())


@pytest.mark.blender
@pytest.mark.parametrize("first_save", [True, False], ids=["unsaved file", "saved file"])
def test_the_preview_and_the_last_lookup_are_stored_relative_and_an_unapplied_material_is_kept(
        tmp_path, monkeypatch, registered_addon, first_save):
    """Saved, a material's preview image and the scene's last baked lookup (what Apply builds a
    material from) are stored relative to the .blend like its lookups, so they move with it; a
    material applied to nothing survives the save and reopening."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "temp"))
    (tmp_path / "temp").mkdir()
    sc = bpy.context.scene
    blend = tmp_path / "project" / "scene.blend"
    blend.parent.mkdir()
    if not first_save:
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    folder = Path(properties.output_dir(sc.specgen))
    folder.mkdir(parents=True, exist_ok=True)
    info = bake.bake_atlas(_table(), folder / "ball_lookup.exr")
    bake.save_atlas_info(info, folder / "ball_lookup.json")
    mat = render.make_material("SpecGen ball", info)                 # applied to nothing
    preview = bpy.data.images.new("SpecGen ball preview", 4, 4)
    preview.filepath_raw = str(folder / "ball_preview.png")
    preview.file_format = "PNG"
    preview.save()
    preview.use_fake_user = True
    mat["specgen_preview"] = preview.name
    sc.specgen.atlas_json = str(folder / "ball_lookup.json")

    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert sc.specgen.atlas_json == "//specgen/ball_lookup.json"
    assert bpy.data.images["SpecGen ball preview"].filepath == "//specgen/ball_preview.png"
    moved = tmp_path / "moved"
    shutil.move(str(blend.parent), str(moved))
    bpy.ops.wm.open_mainfile(filepath=str(moved / "scene.blend"))
    assert "SpecGen ball" in bpy.data.materials                      # kept by its fake user
    assert Path(travel.scene_atlas_json(bpy.context.scene.specgen)) == moved / "specgen" / "ball_lookup.json"
    assert Path(bpy.path.abspath(bpy.data.images["SpecGen ball preview"].filepath)).is_file()


@pytest.mark.blender
@pytest.mark.parametrize("theirs", [["ball_lookup.json", "ball.npz", "ball_lookup.g00.exr"], ["ball_preview.png"]],
                         ids=["whole set", "one file"])
def test_first_save_beside_another_blends_set_renames_this_set_and_touches_none_of_theirs(
        tmp_path, monkeypatch, registered_addon, theirs):
    """Two .blend files beside each other share ``specgen/``: an unsaved file's set of the same
    stem moves in under the next free stem, whole, and the other file's set is left as it was."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "temp"))
    sc = bpy.context.scene
    unsaved = Path(properties.output_dir(sc.specgen))
    unsaved.mkdir(parents=True)
    from blend_reopen import sphere_scene_with_material

    mat, before = sphere_scene_with_material(unsaved, "ball", _table())
    sc.specgen.atlas_json = str(unsaved / "ball_lookup.json")
    shared = tmp_path / "project" / "specgen"
    shared.mkdir(parents=True)
    for name in theirs:
        (shared / name).write_bytes(b"the other .blend's " + name.encode())

    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "project" / "second.blend"))
    for name in theirs:                                                  # theirs untouched
        assert (shared / name).read_bytes() == b"the other .blend's " + name.encode()
    assert not any(unsaved.iterdir())                                    # ours moved, whole
    assert mat["specgen_atlas"] == "//specgen/ball.001_lookup.exr"
    assert all(p.startswith("//specgen/ball.001_lookup.g") for p in mat["specgen_atlas_groups"])
    assert sc.specgen.atlas_json == "//specgen/ball.001_lookup.json"
    info = bake.load_atlas_info(shared / "ball.001_lookup.json")
    assert info.path == shared / "ball.001_lookup.exr"                   # the description follows
    assert (shared / "ball.001.npz").is_file()
    after = render.SpectralRenderJob(sc, None, samples=1, resolution=(16, 16)).run()
    np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-7)


@pytest.mark.blender
def test_save_copy_of_an_unsaved_file_leaves_the_open_file_rendering(tmp_path, monkeypatch, registered_addon):
    """File → Save Copy writes the copy beside its lookups (moved out of the temporary folder),
    and the open file, still unsaved, keeps finding them: it renders the same."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "temp"))
    sc = bpy.context.scene
    unsaved = Path(properties.output_dir(sc.specgen))
    unsaved.mkdir(parents=True)
    from blend_reopen import sphere_scene_with_material

    mat, before = sphere_scene_with_material(unsaved, "ball", _table())
    copy = tmp_path / "copies" / "copy.blend"
    copy.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(copy), copy=True)
    assert bpy.data.filepath == ""                                       # still the unsaved file
    assert (copy.parent / "specgen" / "ball_lookup.json").is_file()      # the copy's lookups
    assert Path(mat["specgen_atlas"]) == copy.parent / "specgen" / "ball_lookup.exr"
    after = render.SpectralRenderJob(sc, None, samples=1, resolution=(16, 16)).run()
    np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-7)
    out = _reopen(copy, tmp_path / "copy.npy")                           # and the copy renders too
    assert "RENDERED" in out, out
    np.testing.assert_allclose(np.load(tmp_path / "copy.npy"), before, rtol=1e-5, atol=1e-7)
