"""*Pack Into .blend*: a .blend copied alone (without its ``specgen/`` folder) to another folder,
opened in a new process, bakes its lookups again from the compact material packed inside it and
renders the same spectral stack (headless, bpy module)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import PKG, addon_module

bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
travel = addon_module("ops.travel")

from blend_reopen import reopen_and_render as _reopen
from blend_reopen import small_table, sphere_scene_with_material


def _table():
    return small_table(albedo=(0.6, 0.3, 0.1), alpha=0.25, gloss=0.2)


def _project(tmp_path):
    """An empty file, and the folder ``project/specgen/`` its material's lookups will be in."""
    project = tmp_path / "project"
    (project / "specgen").mkdir(parents=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return project, project / "specgen"


@pytest.mark.slow
@pytest.mark.blender
def test_a_packed_blend_copied_alone_rebuilds_its_lookups_and_renders_the_same(tmp_path):
    project, lookups = _project(tmp_path)
    PKG.register()
    try:
        sc = bpy.context.scene
        mat, before = sphere_scene_with_material(lookups, "ball", _table())
        thumbnail = bpy.data.images.new("SpecGen ball preview", 4, 4)     # as Generate leaves it
        thumbnail.filepath_raw = str(lookups / "ball_preview.png")
        thumbnail.file_format = "PNG"
        thumbnail.save()
        mat["specgen_preview"] = thumbnail.name

        assert bpy.ops.specgen.pack_materials() == {"FINISHED"}
        assert sc.specgen_pack
        assert thumbnail.packed_file is not None                          # the panel's thumbnail too
        n, size = travel.packed_total()
        assert n == 1 and size == (lookups / "ball.npz").stat().st_size
        blend = project / "scene.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
        # the .blend grows by the compact file only (not by the lookups)
        assert blend.stat().st_size < size + 2_000_000
        assert travel.packed_image(mat).filepath == "//specgen/ball.npz"   # where Unpack writes it
    finally:
        PKG.unregister()

    alone = tmp_path / "elsewhere" / "copied alone"
    alone.mkdir(parents=True)
    shutil.copy2(blend, alone / "scene.blend")
    out = _reopen(alone / "scene.blend", tmp_path / "after.npy")
    assert "baked again from the compact material packed into the .blend" in out and "RENDERED" in out, out
    after = np.load(tmp_path / "after.npy")
    psnr = 10 * np.log10(before.max() ** 2 / np.mean((after - before) ** 2))
    assert psnr >= 60.0, psnr
    assert sorted(p.name for p in (alone / "specgen").iterdir() if p.name.startswith("ball")) == sorted(
        p.name for p in lookups.iterdir() if p.name != "ball_preview.png")  # the set, written back


@pytest.mark.blender
def test_packing_refuses_a_material_without_its_compact_file_and_unpack_removes_the_copy(tmp_path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    PKG.register()
    try:
        info = bake.bake_atlas(_table(), tmp_path / "ball_lookup.exr")
        mat = render.make_material("SpecGen ball", info)
        with pytest.raises(travel.SpecGenError, match="'SpecGen ball' has no compact material file to pack"):
            travel.pack(mat)
        _table().save(tmp_path / "ball.npz", compact=True)
        assert travel.pack(mat) == (tmp_path / "ball.npz").stat().st_size
        assert travel.pack(mat) == (tmp_path / "ball.npz").stat().st_size    # once, not twice
        assert len([i for i in bpy.data.images if i.name.startswith(travel.PACKED_PREFIX)]) == 1
        assert bpy.ops.specgen.pack_materials(unpack=True) == {"FINISHED"}
        assert travel.packed_image(mat) is None and not bpy.context.scene.specgen_pack
        assert not [i for i in bpy.data.images if i.name.startswith(travel.PACKED_PREFIX)]
        assert (tmp_path / "ball.npz").is_file()
    finally:
        PKG.unregister()


@pytest.mark.slow
@pytest.mark.blender
def test_a_render_bakes_lookups_deleted_after_opening_again_from_the_packed_copy(tmp_path):
    lookups = tmp_path / "specgen"
    lookups.mkdir()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    PKG.register()
    try:
        mat, before = sphere_scene_with_material(lookups, "ball", _table())
        travel.pack(mat)
        for f in lookups.iterdir():            # lookups and compact file gone while the file is open
            f.unlink()
        warnings = []
        after = render.SpectralRenderJob(bpy.context.scene, None, samples=1, resolution=(16, 16),
                                         warn=warnings.append).run()
        assert any("baked again from the compact material packed into the .blend" in w for w in warnings), warnings
        assert 10 * np.log10(before.max() ** 2 / np.mean((after - before) ** 2)) >= 60.0
    finally:
        PKG.unregister()


@pytest.mark.slow
@pytest.mark.blender
def test_save_as_elsewhere_keeps_the_packed_path_and_a_copy_rebuilds_beside_itself(tmp_path):
    """Blender rebases a datablock's relative path on Save As into another folder: the packed
    copy's path still names the set's compact file, and the new .blend copied alone bakes its
    lookups again into ``specgen/`` beside itself, not into a folder outside it."""
    project, lookups = _project(tmp_path)
    PKG.register()
    try:
        mat, before = sphere_scene_with_material(lookups, "ball", _table())
        assert bpy.ops.specgen.pack_materials() == {"FINISHED"}
        bpy.ops.wm.save_as_mainfile(filepath=str(project / "scene.blend"))
        saved_as = tmp_path / "other" / "new.blend"
        saved_as.parent.mkdir()
        bpy.ops.wm.save_as_mainfile(filepath=str(saved_as))
        img = travel.packed_image(mat)
        assert Path(bpy.path.abspath(img.filepath)).resolve() == lookups / "ball.npz", img.filepath
        assert Path(travel.atlas_groups(mat)[0]).resolve().parent == lookups
    finally:
        PKG.unregister()

    alone = tmp_path / "far" / "a" / "b"
    alone.mkdir(parents=True)
    shutil.copy2(saved_as, alone / "new.blend")
    out = _reopen(alone / "new.blend", tmp_path / "after.npy")
    assert "RENDERED" in out, out
    assert sorted(p.name for p in (alone / "specgen").iterdir()) == sorted(p.name for p in lookups.iterdir())
    assert sorted(p.relative_to(tmp_path / "far").as_posix() for p in (tmp_path / "far").rglob("*.npz")) == [
        "a/b/specgen/ball.npz"]
    psnr = 10 * np.log10(before.max() ** 2 / np.mean((np.load(tmp_path / "after.npy") - before) ** 2))
    assert psnr >= 60.0, psnr
