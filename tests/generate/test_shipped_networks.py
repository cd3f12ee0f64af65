"""Two shipped networks: one for a sphere copied from a canonical frame, one for a sphere resampled
from a photo; the pipeline picks by how the sphere was cut, given weights override the choice."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.model.runtime import inference as infer
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.model import DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS, shipped_weights
from specgen_addon.evaluation.trained_network import antialiased_input, displaced_input
from specgen_standins import RampMaterial

BANDS = np.array([450.0, 650.0])


@pytest.fixture(scope="module")
def canonical():
    return input_image.render_input(RampMaterial(alpha=0.08))


def test_a_canonical_render_is_copied(canonical):
    crop = input_image.crop_sphere(canonical)
    assert crop.copied
    assert np.array_equal(crop.image, input_image.prepare_sphere_array(canonical))


def test_an_off_grid_sphere_is_resampled(canonical):
    assert not input_image.crop_sphere(displaced_input(canonical, 0.5)).copied


def test_a_sphere_framed_at_another_size_is_resampled():
    big = input_image.render_input(RampMaterial(alpha=0.08), size=2 * input_image.CANONICAL_SIZE)
    assert not input_image.crop_sphere(big).copied


def test_an_antialiased_sphere_is_resampled():
    image = antialiased_input(RampMaterial(alpha=0.08), size=32, supersample=2, border_px=4)
    assert not input_image.crop_sphere(image).copied


def test_shipped_weights_name_one_network_per_kind_of_crop():
    assert shipped_weights(True) == DEFAULT_WEIGHTS
    assert shipped_weights(False) == RESAMPLED_WEIGHTS
    assert DEFAULT_WEIGHTS != RESAMPLED_WEIGHTS


def test_both_shipped_networks_have_their_graphs_and_fit_the_budget():
    folder = DEFAULT_WEIGHTS.parent
    for w in (DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS):
        assert w.is_file()
        assert all(p.is_file() for p in infer.onnx_paths(w))
    total = sum(p.stat().st_size for p in folder.iterdir() if p.is_file())
    assert total <= 40e6, f"weights/ holds {total / 1e6:.1f} MB, over the 40 MB budget"


def test_generate_brdf_without_weights_uses_the_network_for_how_the_sphere_was_cut(canonical):
    copied = infer.generate_brdf(canonical, wavelengths_nm=BANDS)
    resampled = infer.generate_brdf(displaced_input(canonical, 0.5), wavelengths_nm=BANDS)
    assert copied.metadata["weights"] == str(DEFAULT_WEIGHTS)
    assert copied.metadata["input_sphere"] == "copied"
    assert resampled.metadata["weights"] == str(RESAMPLED_WEIGHTS)
    assert resampled.metadata["input_sphere"] == "resampled"
    assert not np.allclose(copied.values, resampled.values)


def test_given_weights_serve_every_input(canonical):
    t = infer.generate_brdf(displaced_input(canonical, 0.5), weights=DEFAULT_WEIGHTS, wavelengths_nm=BANDS)
    assert t.metadata["weights"] == str(DEFAULT_WEIGHTS)


def test_the_pipeline_chooses_by_the_photo_not_by_its_own_crop(canonical):
    # generate() crops the photo, then hands the (whole-pixel) crop on: the choice must follow the photo
    from specgen_addon.generate.pipeline import generate

    out = generate(displaced_input(canonical, 0.5), refine=False, wavelengths_nm=BANDS)
    assert out.table.metadata["weights"] == str(RESAMPLED_WEIGHTS)
    assert out.table.metadata["input_sphere"] == "resampled"
    out = generate(canonical, refine=False, wavelengths_nm=BANDS)
    assert out.table.metadata["weights"] == str(DEFAULT_WEIGHTS)
    assert out.table.metadata["input_sphere"] == "copied"


def test_the_shipped_resampled_graphs_match_its_torch_weights():
    pytest.importorskip("onnxruntime")
    be_t = infer.get_backend(RESAMPLED_WEIGHTS, "torch")
    x = np.random.default_rng(1).random((1, 3, be_t.cfg.image_size, be_t.cfg.image_size)).astype(np.float32)
    u = np.linspace(-1, 1, 3).astype(np.float32)
    for ta, tb in zip(infer.get_backend(RESAMPLED_WEIGHTS, "onnx").make_tables(x, u), be_t.make_tables(x, u)):
        assert np.abs(ta - tb.numpy()).max() < 1e-3 * max(1.0, float(np.abs(ta).max()))


def test_infer_says_which_network_served_a_photo(canonical, tmp_path, capsys):
    from specgen_addon.cli.app import main as cli_main
    from specgen_addon.common.image_io import write_exr

    photo = displaced_input(canonical, 0.5)
    path = write_exr(tmp_path / "photo.exr", {c: photo[..., i] for i, c in enumerate("RGB")})
    out = tmp_path / "t.npz"
    assert cli_main(["infer", str(path), "-o", str(out), "--bands", "2", "--no-refine", "--quiet"]) == 0
    assert f"network: {RESAMPLED_WEIGHTS} (sphere resampled)" in capsys.readouterr().out


def test_the_thin_film_fit_models_the_blur_of_a_resampled_sphere_only(canonical, monkeypatch):
    """``model="thin-film"``: a copied sphere is fitted without a blur model (its pixels are the
    frame's), a resampled one with the refinement's blur candidates (docs/thin_film_fit.md)."""
    from specgen_addon.generate import pipeline
    from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX

    seen = []

    class Stop(Exception):
        pass

    def fake_fit(photo, lighting=None, clip_level=None, progress=None, cancel=None, blur_px=(0.0,)):
        seen.append(tuple(blur_px))
        raise Stop

    monkeypatch.setattr(pipeline, "fit_thin_film", fake_fit)
    for image in (canonical, displaced_input(canonical, 0.5)):
        with pytest.raises(Stop):
            pipeline.generate(image, model="thin-film")
    assert seen == [(0.0,), tuple(BLUR_CANDIDATES_PX)]
