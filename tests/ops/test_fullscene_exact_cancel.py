"""Esc inside the exact direct-light render of a Full Scene render stops it there.

From the panel, the Full Scene job's exact render (direct light on SpecGen surfaces, after the
band renders) runs its Cycles renders as Blender render jobs, like the band renders, so Esc stops
Cycles inside them. The bpy module has no event loop: the test delivers the cancel the way
Blender does (its ``render_cancel`` handler, as ``tests/ops/test_render_settings.py``) to the first
exact render and checks that the job stops there, puts the scene back and writes nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module  # after the bpy skip

from specgen_addon.bake.closure_fit import ggx_lobe
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.common.errors import Cancelled

pytestmark = pytest.mark.blender

bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")
fullscene = addon_module("ops.render_fullscene")
exact_direct = addon_module("ops.exact_direct")
settings = addon_module("ops.render_settings")
convert = addon_module("ops.scene_convert")
scene_mod = addon_module("ops.scene")

WL = np.array([450.0, 550.0, 650.0])


def _plastic(th, td, pd):
    wi, wo = io_from_half_diff(th, td, pd)
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    return above * (np.array([0.6, 0.4, 0.2]) / np.pi + ggx_lobe(wi, wo, 0.3)[:, None] * 0.1)


def test_esc_inside_the_exact_render_stops_the_full_scene_job_and_writes_nothing(tmp_path, monkeypatch):
    info = bake.bake_atlas(BRDFTable.tabulate(_plastic, WL), tmp_path / "t.exr")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    scene_mod.add_mesh(sc, "sphere").data.materials.append(render.make_material("SpecGen esc", info))
    scene_mod.add_sun(sc, (0.35, 0.45, 0.82))
    sc.render.resolution_x = sc.render.resolution_y = 12
    sc.cycles.samples = 1
    before = convert.fingerprint()
    exact_calls = []

    def band_render(scene, layer, interactive):   # the exact renders' start, as Esc meets it
        exact_calls.append(interactive)

        def esc_pressed():
            for handler in list(bpy.app.handlers.render_cancel):
                handler(scene, None)
            return {"RUNNING_MODAL"}

        yield from settings.render_job(esc_pressed)

    monkeypatch.setattr(exact_direct, "band_render", band_render)
    out = tmp_path / "out"
    out.mkdir()
    job = fullscene.FullSceneRenderJob(sc, out / "s.exr", WL, interactive=True, warn=lambda _: None,
                                       log=lambda _: None)
    with pytest.raises(Cancelled, match="inside a band render"):
        job.run()
    assert exact_calls == [True]                   # the band renders ran; the first exact one stopped
    assert convert.fingerprint() == before         # sockets, held-out slots, settings: all put back
    assert "SpecGen holdout" not in bpy.data.materials
    assert list(out.iterdir()) == []
