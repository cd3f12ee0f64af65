"""A spectral table exports a spectral RGL ``.bsdf`` that Mitsuba 3 renders in its spectral variant
(``scalar_spectral``, the ``measured`` plugin) as our renderer renders the table (≥ 35 dB).

Both images are linear sRGB: Mitsuba's film integrates the wavelengths it samples with its CIE 1931
fit; ours are our spectral render's bands, interpolated linearly in λ as the ``measured`` plugin
does (held constant beyond the first and last band), through the CIE 1931 tables. The two
colour conversions differ by a few per cent per channel: each is normalised by its own render of a
white Lambertian sphere under the same lights (one factor per channel)."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.brdf.formats.export import table_to_rgl
from specgen_addon.brdf.formats.rgl import read_rgl
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.evaluation.protocol import DISTANT_LIGHTS
from specgen_addon.render import Scene, metrics, sphere_geometry
from specgen_addon.render.analytic import GGXReflector, Lambertian
from specgen_addon.spectral.spectra import spectral_to_linear_srgb

MIN_DB = 35.0
WL = np.linspace(400.0, 700.0, 8)
#: a green-yellow base: the export's spectrum, not a grey, decides Mitsuba's colour
ALBEDO = np.array([0.1, 0.15, 0.3, 0.6, 0.7, 0.5, 0.3, 0.2])
N, SS = 64, 8                          # Mitsuba's pixels; our supersampling per axis
DENSE = np.arange(360.0, 831.0, 1.0)   # Mitsuba's spectral range


def _coloured_table() -> BRDFTable:
    spec, base = GGXReflector(alpha=0.2, kd=0.0), Lambertian(ALBEDO, WL)

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return spec.eval(wi, wo, WL) + base.eval(wi, wo, WL)
    return BRDFTable.tabulate(fn, WL)


def _to_rgb(spectral: np.ndarray) -> np.ndarray:
    """Linear sRGB of a radiance image on ``WL``, linear in λ between bands, constant beyond."""
    hat = np.stack([np.interp(DENSE, WL, e) for e in np.eye(WL.size)])          # (Λ, dense)
    return spectral_to_linear_srgb(spectral @ hat, DENSE, white=None)


def _mitsuba(mi, bsdf: dict, spp: int) -> np.ndarray:
    lights = {f"light{i}": {"type": "directional", "direction": [-c for c in light.direction],
                            "irradiance": {"type": "uniform", "value": float(light.irradiance)}}
              for i, light in enumerate(DISTANT_LIGHTS)}
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": N, "height": N, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "stratified", "sample_count": spp}},
        "sphere": {"type": "sphere", "bsdf": bsdf}, **lights})
    return np.asarray(mi.render(scene), dtype=np.float64)


@pytest.mark.slow
def test_mitsuba_spectral_renders_an_exported_spectral_rgl_file_as_our_renderer_renders_the_table(tmp_path):
    mi = pytest.importorskip("mitsuba")
    if "scalar_spectral" not in mi.variants():
        pytest.skip("this Mitsuba build has no scalar_spectral variant")
    mi.set_variant("scalar_spectral")
    table = _coloured_table()
    path = table_to_rgl(table, tmp_path / "coloured.bsdf")
    exported = read_rgl(path)
    assert exported.is_spectral and np.allclose(exported.wavelengths, WL)

    ours = Scene(sphere_geometry(N * SS), DISTANT_LIGHTS).render_spectral(table, WL)
    ref = _to_rgb(np.where(ours.mask[..., None], ours.spectral, 0.0).reshape(N, SS, N, SS, -1).mean((1, 3)))
    inside = ours.mask.reshape(N, SS, N, SS).all((1, 3))
    theirs = _mitsuba(mi, {"type": "measured", "filename": str(path)}, 256)

    white_ours = _to_rgb(Scene(sphere_geometry(N), DISTANT_LIGHTS).render_spectral(Lambertian(1.0), WL).spectral)
    white_theirs = _mitsuba(mi, {"type": "diffuse", "reflectance": {"type": "uniform", "value": 1.0}}, 64)
    scale = white_theirs[inside].sum(0) / white_ours[inside].sum(0)
    assert np.all(np.abs(scale / scale.mean() - 1.0) < 0.2)            # the conversions are alike
    psnr = metrics.spectral_metrics(ref, theirs / scale, inside).psnr_mean
    print(f"Mitsuba scalar_spectral vs our renderer: {psnr:.1f} dB")
    assert psnr >= MIN_DB
