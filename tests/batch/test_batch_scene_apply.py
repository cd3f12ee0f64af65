"""batch.py --scene FILE --apply IMG:OBJECT[:lighting] --frames LIST: photos put on objects of an
ordinary scene headless, then the whole-scene render per frame; every bad value refused in one
sentence (exit 2) before any network run or render, nothing written."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

import batch  # after the bpy skip

demo = addon_module("ops.demo_scenes")
REPO = Path(batch.__file__).resolve().parent
PHOTO = REPO / "examples" / "sphere.png"
pytestmark = pytest.mark.blender


@pytest.fixture(scope="module")
def blend(tmp_path_factory) -> Path:
    """An ordinary scene (floor, three Principled spheres, area light, sun, HDRI world), saved."""
    sc = demo.ordinary_scene(samples=2, size=(20, 14))
    sc.frame_start, sc.frame_end = 1, 3
    path = tmp_path_factory.mktemp("scene") / "ordinary.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.mark.parametrize("extra,message", [
    (["--apply", "nope.png:Red"], "nope.png"),
    (["--apply", f"{PHOTO}:Nothing"], "scene 'Scene' has no object 'Nothing'"),
    (["--apply", f"{PHOTO}:Area"], "object 'Area' is a light, not a mesh"),
    (["--apply", f"{PHOTO}:Red:colour=red"], "unknown option 'colour'"),
    (["--apply", f"{PHOTO}:Red:env=no-such-map"], "no-such-map"),
    (["--apply", f"{PHOTO}:Red", f"{PHOTO}:Red"], "more than one photo"),
    (["--apply", f"{REPO / 'README.md'}:Red"], "README.md"),
    (["--frames", "3-1"], "runs backwards"),
])
def test_bad_apply_and_frames_fail_in_one_sentence_before_any_work(blend, tmp_path, capsys, extra,
                                                                    message):
    out = tmp_path / "out"
    code = batch.main(["--scene", str(blend), "--out", str(out), "--bands", "4", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and message in err, err
    assert not any(out.rglob("*.exr")) and not (out / "lookup").exists()


def test_a_bad_light_of_an_apply_photo_fails_in_one_sentence_before_any_work(blend, tmp_path, capsys):
    """A light without a direction, a chrome ball not found, a panorama of the wrong aspect."""
    from PIL import Image

    from specgen_addon.common.image_io import write_exr

    black = tmp_path / "chrome.png"
    Image.fromarray(np.zeros((64, 64, 3), np.uint8)).save(black)
    pano = write_exr(tmp_path / "room.exr", {c: np.ones((20, 30), np.float32) for c in "RGB"})
    out = tmp_path / "out"
    for opts, message in (("light=2", "a light needs a direction"),
                          (f"light-probe={black}", "chrome ball not found"),
                          (f"env={pano}", "twice as wide as it is high")):
        code = batch.main(["--scene", str(blend), "--out", str(out), "--bands", "4",
                           "--apply", f"{PHOTO}:Red:{opts}"])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err.count("\n") == 0 and message in err, err
        assert not any(out.rglob("*.exr"))


def test_scene_only_options_need_a_scene(tmp_path, capsys):
    code = batch.main(["--image", str(PHOTO), "--out", str(tmp_path), "--frames", "1-2"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--frames needs --scene" in err


@pytest.mark.slow
def test_batch_applies_a_photo_to_an_object_and_renders_each_frame(blend, tmp_path):
    from specgen_addon.render.spectral_exr import read_spectral_exr

    out = tmp_path / "out"
    cmd = [sys.executable, str(REPO / "batch.py"), "--scene", str(blend), "--out", str(out),
           "--apply", f"{PHOTO}:Red:rotation=0,key-light=on", "--frames", "1,3", "--bands", "5",
           "--no-refine"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "material 'SpecGen sphere' applied to 'Red'" in done.stdout
    assert "Saved:" not in done.stdout and "full-scene spectral render of" in done.stdout   # Cycles' lines need --verbose
    for frame in (1, 3):
        exr = out / f"Scene_Camera_f{frame:04d}.exr"
        image = read_spectral_exr(exr)
        assert image.values.shape == (14, 20, 5) and image.header["specgenFrame"] == str(frame)
        assert exr.with_name(exr.stem + "_preview.png").is_file()
    assert not (out / "Scene_Camera_f0002.exr").exists()
    assert not (out / "lookup").exists()            # only the renders stay without --keep-lookups
    # the same run again: the outputs exist, refused up front unless --overwrite
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 2 and "already exists" in again.stderr


@pytest.mark.slow
def test_an_apply_photo_takes_infers_photo_options(blend, tmp_path):
    """The room's lights with colours and ambient, the circle given, its preview: as infer does."""
    out = tmp_path / "out"
    preview = tmp_path / "circle.png"
    cmd = [sys.executable, str(REPO / "batch.py"), "--scene", str(blend), "--out", str(out),
           "--apply", (f"{PHOTO}:Red:light=30,20,1.5,3200K,light=-40,10,0.3,0.8/0.9/1,ambient=0.05,"
                       f"circle=64,64,64,circle-preview={preview},refine=off"), "--bands", "4", "--preview"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "sphere: centre (64.00, 64.00) px, radius 64.00 px (given)" in done.stdout
    assert "light az 30° el 20° ×1.5 3200K + light az -40° el 10° ×0.3 0.8/0.9/1 + ambient 0.05" in done.stdout
    assert "self-reproduction of the network alone" in done.stdout and preview.is_file()


def test_preview_renders_a_quarter_size_frame_and_leaves_the_file_settings(blend, tmp_path):
    from specgen_addon.render.spectral_exr import read_spectral_exr

    out = tmp_path / "out"
    assert batch.main(["--scene", str(blend), "--out", str(out), "--bands", "4", "--preview",
                       "--frames", "2"]) == 0
    image = read_spectral_exr(out / "Scene_Camera_f0002.exr")
    assert image.values.shape == (3, 5, 4)                      # 25 % of 20×14
    sc = bpy.context.scene
    assert (sc.render.resolution_percentage, sc.cycles.samples) == (100, 2)
