"""Undo after Generate, headless with the bpy module (as in tests/test_apply_undo.py): one Ctrl-Z
removes what Generate made (its material, node group and preview image) and nothing the user did
before it; redo brings them back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import PKG, addon_module

scene_mod = addon_module("ops.scene")

from specgen_addon.render import sphere_geometry
from specgen_addon.render.analytic import Lambertian
from specgen_addon.render.lights import DistantLight
from specgen_addon.render.renderer import render_spectral


def _state() -> tuple:
    return (sorted(o.name for o in bpy.data.objects), sorted(m.name for m in bpy.data.materials),
            sorted(g.name for g in bpy.data.node_groups), sorted(i.name for i in bpy.data.images))


def _sphere_png(path: Path) -> Path:
    from PIL import Image

    img = render_spectral(Lambertian(albedo=0.5), sphere_geometry(64), lights=[DistantLight((0, 0, 1))],
                          wavelengths_nm=np.array([450.0, 550.0, 650.0])).spectral
    rgb = np.clip(np.repeat(img.mean(-1, keepdims=True), 3, -1), 0, 1)
    Image.fromarray((rgb * 255).astype(np.uint8)).save(path)
    return path


@pytest.mark.slow
@pytest.mark.blender
def test_one_undo_after_generate_removes_only_what_generate_made(tmp_path):
    from specgen_addon.model import DEFAULT_WEIGHTS

    if not Path(DEFAULT_WEIGHTS).is_file():
        pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    PKG.register()
    try:
        s = bpy.context.scene.specgen
        s.image_path = str(_sphere_png(tmp_path / "sphere.png"))
        s.output_dir = str(tmp_path / "out")
        s.bands = 4
        s.refine = False
        bpy.ops.ed.undo_push(message="settings")
        scene_mod.add_mesh(bpy.context.scene, "sphere")                 # the user's own step
        bpy.ops.ed.undo_push(message="add the sphere")
        before = _state()

        assert bpy.ops.specgen.generate_brdf("EXEC_DEFAULT", True) == {"FINISHED"}   # as from a button
        after = _state()
        made = [n for a, b in zip(after, before) for n in set(a) - set(b)]
        assert any(n.startswith("SpecGen ") for n in made) and after[0] == before[0]

        assert bpy.ops.ed.undo() == {"FINISHED"}
        assert _state() == before                 # Generate's datablocks gone, the sphere kept
        assert bpy.ops.ed.redo() == {"FINISHED"}
        assert _state() == after
        previews = [i.name for i in bpy.data.images if i.name.startswith("SpecGen ")]
        assert previews
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "saved.blend"))
        bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "saved.blend"))
        assert all(name in bpy.data.images for name in previews)   # the thumbnail survives the save
    finally:
        PKG.unregister()
