"""``infer`` and ``tabulate`` export the BRDF itself: RGL ``.bsdf`` (spectral where the table is)
and MERL ``.binary`` (RGB). An exported ``.bsdf`` renders like the table it came from, in our
renderer and in Mitsuba 3's ``measured`` plugin (written by the format's authors)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.render import metrics
from specgen_addon.common.errors import SpecGenError
from specgen_addon.evaluation.protocol import DISTANT_LIGHTS
from specgen_addon.brdf.formats import load_brdf
from specgen_addon.brdf.formats.export import table_to_rgl, write_output
from specgen_addon.brdf.formats.merl import read_merl
from specgen_addon.render import Scene, sphere_geometry
from specgen_addon.render.analytic import GGXReflector
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable

REPO = Path(__file__).resolve().parents[2]
MIN_DB = 35.0


@pytest.fixture(scope="module")
def spectral_table() -> BRDFTable:
    """A glossy, coloured spectral table (GGX α 0.2 over a diffuse base), 8 bands."""
    brdf = GGXReflector(alpha=0.2)
    wl = np.linspace(400.0, 700.0, 8)
    return BRDFTable.tabulate(lambda th, td, pd: brdf.eval(*io_from_half_diff(th, td, pd), wl), wl,
                              metadata={"description": "GGX test"})


def _psnr(ref, got, mask) -> float:
    return metrics.spectral_metrics(ref, got, mask).psnr_mean


def test_an_unknown_output_suffix_is_refused_before_any_work(tmp_path, rgl_files):
    for cmd in (["tabulate", str(rgl_files["felt"]), "-o"], ["infer", str(REPO / "examples" / "sphere.png"), "-o"]):
        done = subprocess.run([sys.executable, "-m", "specgen_addon", *cmd, str(tmp_path / "x.exr")],
                              capture_output=True, text=True, cwd=REPO, timeout=120, check=False)
        assert done.returncode != 0 and "output must end in .npz or .bsdf or .binary" in done.stderr, done.stderr
        assert "Traceback" not in done.stderr and not (tmp_path / "x.exr").exists()


@pytest.mark.slow
def test_tabulate_exports_an_rgl_file_as_merl_and_rgl_and_says_how_big(tmp_path, rgl_files):
    outs = {s: tmp_path / f"felt{s}" for s in (".binary", ".bsdf", ".npz")}
    for out in outs.values():
        done = subprocess.run([sys.executable, "-m", "specgen_addon", "tabulate", str(rgl_files["felt"]),
                               "-o", str(out), "--quiet"], capture_output=True, text=True, cwd=REPO,
                              timeout=600, check=False)
        assert done.returncode == 0, done.stderr
        assert f"wrote {out} (" in done.stdout and "B)" in done.stdout, done.stdout
    table = BRDFTable.load(outs[".npz"])
    merl = read_merl(outs[".binary"]).to_table()
    np.testing.assert_allclose(merl.values, table.values, rtol=5e-3, atol=1e-6)
    scene = Scene(sphere_geometry(64), DISTANT_LIGHTS)
    ref = scene.render_rgb(table)
    assert _psnr(ref.rgb, scene.render_rgb(load_brdf(outs[".bsdf"])).rgb, ref.mask) >= MIN_DB


def test_a_spectral_table_exports_a_spectral_rgl_file_that_renders_alike(spectral_table, tmp_path):
    path = table_to_rgl(spectral_table, tmp_path / "ggx.bsdf")
    bsdf = load_brdf(path)
    assert bsdf.is_spectral and np.allclose(bsdf.wavelengths, spectral_table.wavelengths)
    scene = Scene(sphere_geometry(64), DISTANT_LIGHTS)
    wl = spectral_table.wavelengths
    ref = scene.render_spectral(spectral_table, wl)
    assert _psnr(ref.spectral, scene.render_spectral(bsdf, wl).spectral, ref.mask) >= MIN_DB
    with pytest.raises(SpecGenError, match="already exists|exists"):
        write_output(spectral_table, path)


@pytest.mark.slow
def test_mitsuba_renders_an_exported_rgl_file_as_our_renderer_renders_the_table(spectral_table, tmp_path):
    """RGB file, Mitsuba's RGB variant. Mitsuba picks the measured slice with the camera direction
    (``si.wi``), our renderer with the light's; the exported table is reciprocal (MERL grid), so
    both assignments give the same image. Our side is supersampled 8× per axis to match Mitsuba's
    box-filtered, stratified pixels."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    table = spectral_table.to_rgb()
    path = table_to_rgl(table, tmp_path / "ggx_rgb.bsdf")
    n, ss = 64, 8
    ours = Scene(sphere_geometry(n * ss), DISTANT_LIGHTS).render_rgb(table)
    ref = np.where(ours.mask[..., None], ours.rgb, 0.0).reshape(n, ss, n, ss, 3).mean((1, 3))
    inside = ours.mask.reshape(n, ss, n, ss).all((1, 3))
    lights = {f"light{i}": {"type": "directional", "direction": [-c for c in light.direction],
                            "irradiance": {"type": "rgb", "value": [light.irradiance] * 3}}
              for i, light in enumerate(DISTANT_LIGHTS)}
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": n, "height": n, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "stratified", "sample_count": 256}},
        "sphere": {"type": "sphere", "bsdf": {"type": "measured", "filename": str(path)}}, **lights})
    theirs = np.asarray(mi.render(scene), dtype=np.float64)
    assert _psnr(ref, theirs, inside) >= MIN_DB
