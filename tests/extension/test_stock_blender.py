"""The built extension zip in a stock Blender: Blender's validator accepts it, and with only bpy,
numpy, Blender's bundled modules and the zip's wheels on the import path (torch, colour, scipy,
PIL, skimage, OpenEXR and OpenCV blocked), it installs through Blender's extension API and runs
Generate → Apply → Render Spectral Stack on the example photo on a new file's default scene (the
cube) with the quick preview setting into a readable spectral EXR, in a bounded time it prints."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "scripts" / "build_extension.py"
BLOCKED = ("torch", "colour", "scipy", "PIL", "skimage", "OpenEXR", "onnx", "lazy_loader", "numba", "llvmlite",
           "cv2", "colour_checker_detection")
ZIP_LIMIT_BYTES = 60 * 1024 * 1024
#: Generate → Apply → Render of the default scene with the quick preview must finish within this.
STOCK_BOUND_S = 300.0


def _bpy_root() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None:
        pytest.skip("the bpy wheel is not installed")
    return Path(next(iter(spec.submodule_search_locations)))


def _validator() -> Path:
    path = next(_bpy_root().glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"), None)
    if path is None:
        pytest.skip("the bpy wheel carries no extension validator (bl_pkg/cli/blender_ext.py)")
    return path


def _build(out: Path, wheels: bool) -> Path:
    args = [sys.executable, str(BUILD), "--out", str(out)]
    args += ["--fetch-wheels"] if wheels else ["--no-wheels"]
    done = subprocess.run(args, capture_output=True, text=True, timeout=300)
    if wheels and done.returncode != 0 and "pip" in done.stderr + done.stdout:
        pytest.skip(f"the manifest's wheels could not be fetched: {done.stderr.strip()[-300:]}")
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def full_zip(tmp_path_factory) -> Path:
    return _build(tmp_path_factory.mktemp("zip") / "specgen.zip", wheels=True)


def test_blenders_own_validator_accepts_the_built_zip(tmp_path):
    zip_path = _build(tmp_path / "specgen.zip", wheels=False)
    done = subprocess.run([sys.executable, str(_validator()), "validate", str(zip_path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Success" in done.stdout


def test_full_zip_validates_bundles_its_wheels_and_stays_under_60_mb(full_zip):
    done = subprocess.run([sys.executable, str(_validator()), "validate", str(full_zip)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert full_zip.stat().st_size <= ZIP_LIMIT_BYTES
    with zipfile.ZipFile(full_zip) as zf:
        names = set(zf.namelist())
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    for wheel in manifest["wheels"]:
        assert wheel.removeprefix("./") in names
    assert "specgen_addon/spectral/data/colour_tables.npz" in names
    assert not any(n.startswith(("tests/", "bench/", ".venv/", ".git")) for n in names)


# --------------------------------------------------------------------------- stock Blender
#: What every script below starts with: the packages a stock Blender lacks are blocked, and
#: Blender's bundled modules (OpenImageIO, oslquery, ...), which the bpy module keeps in its wheel,
#: are put on sys.path where a real Blender has them.
STOCK_PRELUDE = r'''
import importlib.abc, json, os, runpy, sys
BLOCKED = set(json.loads(os.environ["SPECGEN_BLOCKED"]))

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"{name} is not in a stock Blender")
        return None

sys.meta_path.insert(0, Block())
import bpy  # noqa: E402
sys.path.append(os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib", "python3.11", "site-packages"))
'''

SCRIPT = STOCK_PRELUDE + r'''
zip_path, image, out = sys.argv[1:4]
r = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                             enable_on_install=True)
assert r == {"FINISHED"}, r
import time
import bl_ext.user_default.specgen.ops.render as render

# a new file's default scene (cube, light, camera; 1920x1080, the default Cycles samples), the
# SpecGen photo on the cube, rendered with the panel's quick preview setting
sc = bpy.context.scene
assert {"Cube", "Light", "Camera"} <= {o.name for o in sc.objects}, [o.name for o in sc.objects]
sc.render.engine = "CYCLES"
s = sc.specgen
s.image_path, s.output_dir = image, out
s.bands, s.lookup_resolution = 5, "45"
s.quick_preview = True
t0 = time.perf_counter()
assert bpy.ops.specgen.generate_brdf() == {"FINISHED"}
t1 = time.perf_counter()
obj = bpy.data.objects["Cube"]
bpy.context.view_layer.objects.active = obj
obj.select_set(True)
assert bpy.ops.specgen.apply() == {"FINISHED"}
assert render.is_specgen_material(obj.active_material)
assert bpy.ops.specgen.render_stack() == {"FINISHED"}
t2 = time.perf_counter()
assert (sc.render.resolution_x, sc.render.resolution_percentage) == (1920, 100)  # restored
assert "SpecGen Result" in bpy.data.images
timing = {"generate_s": t1 - t0, "render_s": t2 - t1, "total_s": t2 - t0,
          "exr": f"{sc.name}_{sc.camera.name}_f{sc.frame_current:04d}.exr"}
roots = {os.path.realpath(p) for p in sys.path if p and os.path.isdir(p)}
outside = sorted({name.split(".")[0] for name, m in list(sys.modules.items())
                  if getattr(m, "__file__", None) and not any(
                      os.path.realpath(m.__file__).startswith(r) for r in roots)})
print("SPECGEN-STOCK-OK", json.dumps({"modules": sorted({n.split(".")[0] for n in sys.modules}),
                                      "outside": outside, **timing}))
'''


def test_stock_blender_installs_the_zip_and_renders_a_spectral_exr(full_zip, tmp_path):
    import importlib.util

    root = _bpy_root()
    site = tmp_path / "site"  # the import path of a stock Blender: bpy and numpy only
    site.mkdir()
    for name in ("bpy", "numpy"):
        origin = Path(importlib.util.find_spec(name).submodule_search_locations[0])
        (site / name).symlink_to(origin)
    home = tmp_path / "home"
    home.mkdir()
    out = tmp_path / "out"
    env = {"HOME": str(home), "PATH": os.environ.get("PATH", ""), "PYTHONPATH": str(site),
           "SPECGEN_BLOCKED": json.dumps(BLOCKED), "PYTHONNOUSERSITE": "1"}
    # -S: no site-packages of this venv (torch, colour, onnxruntime ... stay out of reach)
    done = subprocess.run([sys.executable, "-S", "-c", SCRIPT, str(full_zip),
                           str(REPO / "examples" / "sphere.png"), str(out)],
                          env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    line = next((l for l in done.stdout.splitlines() if l.startswith("SPECGEN-STOCK-OK")), None)
    assert line is not None, done.stdout[-3000:] + done.stderr[-3000:]
    report = json.loads(line.split(" ", 1)[1])
    assert not set(BLOCKED) & set(report["modules"])
    assert "onnxruntime" in report["modules"]  # from the zip's wheel
    # every module came from the stdlib, Blender's own paths or the installed extension
    assert set(report["outside"]) <= {"bl_ext", "numpy", "bpy"}, report["outside"]
    assert root.is_dir()

    print(f"stock Blender, new file's default scene, quick preview: Generate {report['generate_s']:.1f} s, "
          f"Apply + Render {report['render_s']:.1f} s, total {report['total_s']:.1f} s")
    assert report["total_s"] < STOCK_BOUND_S, report

    # read with an independent reader (OpenEXR here, not the extension's OpenImageIO path)
    OpenEXR = pytest.importorskip("OpenEXR")
    exr_path = out / report["exr"]
    with OpenEXR.File(str(exr_path), separate_channels=True) as exr:
        part = exr.parts[0]
        assert part.header["spectralLayoutVersion"] == "1.0"
        assert "AgX" in part.header["specgenPreviewTransform"]     # PNG through Blender's view
        bands = sorted(n for n in part.channels if n.startswith("S0."))
        stack = np.stack([np.asarray(part.channels[n].pixels) for n in bands], -1)
    assert len(bands) == 5 and stack.shape == (270, 480, 5)        # 25 % of 1920×1080
    assert np.all(np.isfinite(stack)) and stack[135, 240].min() > 0  # the cube, lit
    # full-scene mode (the default) renders the world too: the default grey world fills the corners
    assert stack[0, 0].min() > 0 and np.allclose(stack[0, 0], stack[-1, -1], rtol=0.25)
    assert exr_path.with_name(exr_path.stem + "_preview.png").is_file()


# --------------------------------------------------------------------------- image I/O backends
def test_openimageio_backend_writes_exrs_and_pngs_that_openexr_and_pillow_read(tmp_path, monkeypatch):
    OpenEXR = pytest.importorskip("OpenEXR")
    pytest.importorskip("OpenImageIO")
    from PIL import Image

    from specgen_addon.common import image_io

    rng = np.random.default_rng(0)
    planes = {"S0.450,000000nm": rng.random((7, 9)), "R": rng.random((7, 9)), "A": rng.random((7, 9))}
    monkeypatch.setattr(image_io, "_openexr", lambda: None)   # what a stock Blender has
    monkeypatch.setattr(image_io, "_pillow", lambda: None)
    for tiled in (False, True):
        path = image_io.write_exr(tmp_path / f"a{tiled}.exr", planes, attributes={"specgenX": "y z"},
                                  tiled=tiled)
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            part = exr.parts[0]
            assert part.header["specgenX"] == "y z"
            for name, plane in planes.items():
                np.testing.assert_array_equal(part.channels[name].pixels, plane.astype(np.float32))
        channels, header = image_io.read_exr(path)   # and OIIO reads back what it wrote
        assert header["specgenX"] == "y z" and set(channels) == set(planes)
    pixels = rng.integers(0, 256, (5, 6, 3), dtype=np.uint8)
    image_io.write_png8(tmp_path / "p.png", pixels)
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "p.png")), pixels)
    np.testing.assert_allclose(image_io.read_ldr(tmp_path / "p.png"), pixels / 255.0, atol=1e-6)


def test_sphere_is_found_identically_without_scipy_and_skimage(monkeypatch):
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.photo import ndimage_np

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:300, :400]
    disc = (yy - 140) ** 2 + (xx - 210) ** 2 < 110 ** 2
    grey = np.full((300, 400, 3), 0.3) + rng.normal(0, 0.01, (300, 400, 3))
    grey[disc] = [0.8, 0.2, 0.1]
    ref_png = input_image.load_sphere_image(REPO / "examples" / "sphere.png")
    ref_grey = input_image.prepare_sphere_array(grey)
    monkeypatch.setattr(input_image, "_ndimage", lambda: ndimage_np)
    monkeypatch.setattr(input_image, "_ransac_circle", lambda pts, residual_threshold, max_trials:
                        ndimage_np.ransac_circle(pts, residual_threshold, max_trials))
    np.testing.assert_allclose(input_image.load_sphere_image(REPO / "examples" / "sphere.png"), ref_png, atol=1e-6)
    # the sub-pixel refinement starts from RANSAC's circle, which the twins find a hair apart
    # (their random draws differ); the crops then agree to ~10⁻⁴ of the sphere's value
    np.testing.assert_allclose(input_image.prepare_sphere_array(grey), ref_grey, atol=1e-3)


def test_numpy_ndimage_twins_match_scipy():
    ndimage = pytest.importorskip("scipy.ndimage")
    from specgen_addon.photo import ndimage_np

    rng = np.random.default_rng(1)
    mask = rng.random((97, 131)) > 0.55
    for name in ("binary_erosion", "binary_opening", "binary_fill_holes"):
        np.testing.assert_array_equal(getattr(ndimage_np, name)(mask), getattr(ndimage, name)(mask))
    got, n = ndimage_np.label(mask)
    ref, n_ref = ndimage.label(mask)
    assert n == n_ref
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_allclose(ndimage_np.sum(mask, got, np.arange(1, n + 1)),
                               ndimage.sum(mask, ref, index=np.arange(1, n + 1)))
    img = rng.random((40, 50, 3))
    np.testing.assert_allclose(ndimage_np.gaussian_filter(img, (1.3, 1.3, 0)),
                               ndimage.gaussian_filter(img, (1.3, 1.3, 0), mode="nearest"), atol=1e-12)
    np.testing.assert_allclose(ndimage_np.gaussian_filter(img, (0.7, 0.7, 0), mode="constant"),
                               ndimage.gaussian_filter(img, (0.7, 0.7, 0), mode="constant"), atol=1e-12)
    y, x = rng.uniform(-3, 45, 500), rng.uniform(-3, 55, 500)
    np.testing.assert_allclose(ndimage_np.map_coordinates(img[..., 0], [y, x]),
                               ndimage.map_coordinates(img[..., 0], [y, x], order=1, mode="nearest"), atol=1e-12)


BATCH_SCRIPT = STOCK_PRELUDE + r'''
script = sys.argv[1]
sys.argv = ["blender", "--background", "--python", script, "--", *sys.argv[2:]]
runpy.run_path(script, run_name="__main__")
'''


def test_batch_renders_a_table_in_a_stock_blender(tmp_path):
    import importlib.util

    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable

    _bpy_root()
    site = tmp_path / "site"
    site.mkdir()
    for name in ("bpy", "numpy"):
        (site / name).symlink_to(Path(importlib.util.find_spec(name).submodule_search_locations[0]))
    rho = np.array([0.2, 0.5, 0.7])

    def lambert(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return np.where(((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None], rho[None] / np.pi, 0.0)

    BRDFTable.tabulate(lambert, np.array([450.0, 550.0, 650.0])).save(tmp_path / "l.npz")
    env = {"HOME": str(tmp_path), "PATH": os.environ.get("PATH", ""), "PYTHONPATH": str(site),
           "SPECGEN_BLOCKED": json.dumps(BLOCKED), "PYTHONNOUSERSITE": "1"}
    done = subprocess.run([sys.executable, "-S", "-c", BATCH_SCRIPT, str(REPO / "batch.py"), "--brdf",
                           str(tmp_path / "l.npz"), "--out", str(tmp_path / "out"), "--bands", "3",
                           "--wl-min", "450", "--wl-max", "650", "--resolution", "16", "--samples", "1"],
                          env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert (tmp_path / "out" / "l_sphere_studio.exr").is_file()
    assert "Saved:" not in done.stdout
