"""The panel's *Export BRDF* writes the chosen material's BRDF as RGL .bsdf (spectral) or MERL
.binary (RGB) from the compact material file beside its lookups; without that file it says so."""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

bake = addon_module("specgen_addon.bake.lookup")
render = addon_module("ops.render")

from specgen_addon.brdf.formats import load_brdf
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

WL = np.array([450.0, 550.0, 650.0])


def _table() -> BRDFTable:
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None] * np.array([0.2, 0.5, 0.7]) / np.pi
    return BRDFTable.tabulate(fn, WL)


@pytest.mark.slow
@pytest.mark.blender
def test_export_brdf_writes_rgl_and_merl_files_of_the_panels_material(tmp_path, registered_addon):
    table = _table()
    info = bake.bake_atlas(table, tmp_path / "ball_lookup.exr")
    table.save(tmp_path / "ball.npz", compact=True)
    bare = bake.bake_atlas(table, tmp_path / "bare" / "bare_lookup.exr")
    s = bpy.context.scene.specgen
    s.material = render.make_material("SpecGen ball", info)
    assert bpy.ops.specgen.export_brdf(filepath=str(tmp_path / "ball.bsdf")) == {"FINISHED"}
    assert bpy.ops.specgen.export_brdf(filepath=str(tmp_path / "ball.binary")) == {"FINISHED"}
    s.material = render.make_material("SpecGen bare", bare)
    with pytest.raises(RuntimeError, match="has no BRDF file beside its lookups"):
        bpy.ops.specgen.export_brdf(filepath=str(tmp_path / "bare.bsdf"))
    bsdf = load_brdf(tmp_path / "ball.bsdf")
    assert bsdf.is_spectral and np.allclose(bsdf.wavelengths, WL)
    merl = load_brdf(tmp_path / "ball.binary")
    wi = wo = np.array([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(merl.eval_rgb(wi, wo), table.to_rgb().eval(wi, wo), rtol=0.01)
    assert not (tmp_path / "bare.bsdf").exists()
