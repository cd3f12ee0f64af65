"""Shared by the .blend travel tests: a small material table and a reopen-and-render in a new process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from specgen_addon.bake.closure_fit import ggx_lobe
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

REPO = Path(__file__).resolve().parents[1]
WL = np.array([450.0, 550.0, 650.0])

REOPEN = r"""
import json, sys
import numpy as np
sys.path.insert(0, {repo!r})
sys.path.insert(0, {tests!r})
import bpy
from addon_modules import PKG, addon_module
PKG.register()
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
render = addon_module("ops.render")
try:
    stack = render.SpectralRenderJob(bpy.context.scene, None, samples=1, resolution=(16, 16)).run()
    np.save(sys.argv[2], stack)
    print("RENDERED")
except Exception as exc:
    print("REFUSED", exc)
"""


def small_table(albedo=(0.2, 0.5, 0.7), alpha: float = 0.3, gloss: float = 0.1) -> BRDFTable:
    """A Lambert + GGX table on three wavelengths (450, 550, 650 nm)."""
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        above = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
        return above * np.array(albedo) / np.pi + ggx_lobe(wi, wo, alpha)[:, None] * gloss
    return BRDFTable.tabulate(fn, WL)


def reopen_and_render(blend: Path, out: Path) -> str:
    """Open ``blend`` in a new process with the add-on registered, render its spectral stack into
    ``out`` (.npy); the process's output (``RENDERED`` or ``REFUSED <reason>``)."""
    script = REOPEN.format(repo=str(REPO), tests=str(REPO / "tests"))
    done = subprocess.run([sys.executable, "-c", script, str(blend), str(out)], capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def sphere_scene_with_material(folder: Path, stem: str, table: BRDFTable):
    """In the open (empty) file: camera, sphere and sun, and a SpecGen material ``SpecGen <stem>``
    on the sphere, its lookups and compact file written into ``folder`` as Generate writes them.
    Returns (material, its spectral stack rendered now at 16², 1 spp). Needs bpy."""
    from addon_modules import addon_module

    bake, render, scene_mod = (addon_module(m) for m in ("specgen_addon.bake.lookup", "ops.render",
                                                         "ops.scene"))
    import bpy

    sc = bpy.context.scene
    scene_mod.add_camera(sc)
    obj = scene_mod.add_mesh(sc, "sphere")
    scene_mod.add_sun(sc, (0.0, 0.3, 1.0))
    info = bake.bake_atlas(table, folder / f"{stem}_lookup.exr")
    bake.save_atlas_info(info, folder / f"{stem}_lookup.json")
    table.save(folder / f"{stem}.npz", compact=True)
    mat = render.make_material(f"SpecGen {stem}", info)
    obj.data.materials.append(mat)
    return mat, render.SpectralRenderJob(sc, None, samples=1, resolution=(16, 16)).run()
