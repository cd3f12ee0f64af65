r"""Folder and file names with spaces, a backslash and non-ASCII letters work through ``infer``,
``batch.py`` and the .blend travel (packed, moved, its lookups baked again on open).

A backslash is an ordinary character in a POSIX file name (and the separator on Windows, where
the same code takes ``pathlib`` paths); no code may split, quote or re-encode a path by hand."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.model import SpecGen, save_weights

REPO = Path(__file__).resolve().parents[2]
ODD = "mat\u00e9riaux d\u2019\u00e9t\u00e9 \\ \u7d20\u6750"    # spaces, a backslash, é, ’ and CJK
POSIX_ONLY = pytest.mark.skipif(sys.platform == "win32", reason="a backslash separates folders on Windows")


def _odd_folder(tmp_path: Path) -> Path:
    folder = tmp_path / ODD / "sous dossier"
    folder.mkdir(parents=True)
    return folder


@POSIX_ONLY
@pytest.mark.slow
def test_infer_reads_and_writes_paths_with_spaces_a_backslash_and_accents(tmp_path):
    from tiny_model import TINY_MODEL

    from specgen_addon.model import Config

    folder = _odd_folder(tmp_path)
    photo = folder / "boule \u00e9t\u00e9.png"
    shutil.copy(REPO / "examples" / "sphere.png", photo)
    weights = save_weights(SpecGen(Config(**TINY_MODEL)), folder / "r\u00e9seau.pt")
    out = folder / "sortie \u00e9t\u00e9.npz"
    done = subprocess.run([sys.executable, "-m", "specgen_addon", "infer", str(photo), "--weights", str(weights),
                           "--no-refine", "--bands", "4", "--quiet", "-o", str(out)],
                          capture_output=True, text=True, cwd=REPO, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert out.is_file()
    assert re.search(rf"wrote {re.escape(str(out))} \(compact material, \d+\.\d (kB|MB)\)", done.stdout), done.stdout


@POSIX_ONLY
@pytest.mark.slow
@pytest.mark.blender
def test_batch_py_renders_from_and_into_a_folder_with_spaces_a_backslash_and_accents(tmp_path):
    pytest.importorskip("bpy")
    from blend_reopen import small_table

    folder = _odd_folder(tmp_path)
    table = small_table().save(folder / "boule \u00e9t\u00e9.npz", compact=True)
    out = folder / "rendus \u00e9t\u00e9"
    done = subprocess.run([sys.executable, str(REPO / "batch.py"), "--brdf", str(table), "--env", "studio",
                           "--out", str(out), "--bands", "3", "--wl-min", "450", "--wl-max", "650",
                           "--resolution", "16", "--samples", "1", "--keep-lookups"],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    exr = out / "boule \u00e9t\u00e9_sphere_studio.exr"
    assert exr.is_file() and (out / "boule \u00e9t\u00e9_sphere_studio_preview.png").is_file()
    assert f"wrote {exr} (" in done.stdout
    assert any(p.name.startswith("boule \u00e9t\u00e9_lookup.g") for p in (out / "lookup").iterdir())


@POSIX_ONLY
@pytest.mark.slow
@pytest.mark.blender
def test_a_packed_blend_in_such_a_folder_rebuilds_its_lookups_and_renders(tmp_path):
    bpy = pytest.importorskip("bpy")
    from addon_modules import PKG
    from blend_reopen import reopen_and_render, small_table, sphere_scene_with_material
    project = _odd_folder(tmp_path)
    lookups = project / "specgen"
    lookups.mkdir()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    PKG.register()
    try:
        _, before = sphere_scene_with_material(lookups, "boule \u00e9t\u00e9", small_table())
        assert bpy.ops.specgen.pack_materials() == {"FINISHED"}
        blend = project / "sc\u00e8ne \\ 1.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        PKG.unregister()
    elsewhere = tmp_path / "ailleurs \\ \u00fc" / blend.name
    elsewhere.parent.mkdir()
    shutil.copy2(blend, elsewhere)
    out = reopen_and_render(elsewhere, tmp_path / "after.npy")
    assert "RENDERED" in out, out
    after = np.load(tmp_path / "after.npy")
    assert 10 * np.log10(before.max() ** 2 / np.mean((after - before) ** 2)) >= 60.0
    assert (elsewhere.parent / "specgen" / "boule \u00e9t\u00e9.npz").is_file()


@POSIX_ONLY
@pytest.mark.blender
def test_a_preview_image_in_a_folder_with_a_backslash_loads_with_its_pixels(tmp_path):
    bpy = pytest.importorskip("bpy")
    from addon_modules import addon_module

    from specgen_addon.common.image_io import write_png8

    travel = addon_module("ops.travel")
    folder = _odd_folder(tmp_path)
    pixels = np.zeros((4, 6, 3), np.uint8)
    pixels[..., 0] = 255                                  # pure red: exact in any decoding
    png = write_png8(folder / "aper\u00e7u \\ preview.png", pixels)
    img = travel.load_image(png, "SpecGen odd preview")
    try:
        assert img.name == "SpecGen odd preview" and tuple(img.size) == (6, 4)
        rgba = np.array(img.pixels[:]).reshape(4, 6, 4)
        assert np.allclose(rgba[..., :3], [1.0, 0.0, 0.0])
        assert Path(img.filepath_raw) == png              # it still names the file
    finally:
        bpy.data.images.remove(img)
