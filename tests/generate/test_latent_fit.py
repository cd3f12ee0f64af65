"""The latent fit: its per-node head and cheap render agree with the exact paths, it recovers a
photo the decoder can make, it repeats bit for bit, and it refuses bad settings."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from specgen_addon.model.runtime import inference as infer
from specgen_addon.common.errors import Cancelled, SpecGenError
from specgen_addon.photo.sphere_image import SphereCrop
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.generate.latent_fit import (CheapRender, LatentFitOptions, OperatorSamples, decode_table,
                                      fit_latent, unresolved_theta_h_nodes)
from specgen_addon.model import Config, SpecGen, save_weights
from specgen_addon.model.runtime.fast import head_at_nodes, lambda_coords
from specgen_addon.brdf.lookup_reach import phi_d_reach
from specgen_addon.generate.refine import diffuse_floor_of, render_under
from specgen_addon.generate.refine.operator import PhotoOperator
from specgen_addon.render.photo_reproduction import rgb_psnr
from specgen_addon.brdf.table import BRDFTable, grid_angles
from tiny_model import TINY_MODEL

SMALL = {**TINY_MODEL, "spectral_code_knots": 2}
BANDS = np.array([420.0, 500.0, 580.0, 660.0, 740.0])
SIZE = 32                                               # photo size: a 32² sphere keeps the fit quick
FAST = dict(steps=24, refresh_every=12, batch_pixels=128, fit_wavelengths_nm=tuple(BANDS))


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A small AFF network whose output varies with the latent, and an input image for it."""
    torch.manual_seed(3)
    model = SpecGen(Config(**SMALL))
    torch.nn.init.normal_(model.fusion.expand.weight, std=1.0)
    with torch.no_grad():                  # a BRDF of about 0.1 sr⁻¹ (r' 0.6), not clamped to 0
        model.mapping.fc3.bias.fill_(0.6)
    path = save_weights(model, tmp_path_factory.mktemp("w") / "small.pt")
    image = np.random.default_rng(0).uniform(0.05, 0.6, (SIZE, SIZE, 3)).astype(np.float32)
    return path, image


def _encoded(be, image):
    x = torch.from_numpy(infer.resample_square(image, be.cfg.image_size)[None].astype(np.float32))
    with torch.no_grad():
        return be.model.latent(x), be.model.encoder.colour(x)


def test_head_at_nodes_equals_the_grid_head(small):
    path, image = small
    be = infer.get_backend(path, "torch")
    x = infer.resample_square(image, be.cfg.image_size)[None].astype(np.float32)
    u = lambda_coords(be.model, BANDS).numpy()
    tables = be.make_tables(x, u)
    grid = infer.evaluate_grid(be, tables, BANDS.size)                      # μ-law, the fast path
    lo, hi = phi_d_reach()
    rng = np.random.default_rng(1)
    i, j = rng.integers(0, 90, 3000), rng.integers(0, 90, 3000)
    k = lo[i, j] + (rng.random(3000) * (hi[i, j] - lo[i, j] + 1)).astype(int)   # reached nodes
    with torch.no_grad():
        at = head_at_nodes(be.model, tables, torch.from_numpy(i), torch.from_numpy(j), torch.from_numpy(k))
    np.testing.assert_allclose(at.numpy(), grid[i, j, k], rtol=1e-5, atol=1e-6)
    # and the tables of given planes are the tables of the image's planes
    with torch.no_grad():
        again = be.tables.tables_of(be.model.planes(torch.from_numpy(x)), torch.from_numpy(u))
    for a, b in zip(again, tables):
        assert torch.equal(a, b)


def test_the_cheap_render_with_many_samples_approaches_the_renderers_photo(small):
    """The per-sample bookkeeping (radiance, control variate, colour, exposure) against the
    reference renderer: nearest nodes and a dense draw of the map's samples come close to it."""
    path, image = small
    be = infer.get_backend(path, "torch")
    z, c = _encoded(be, image)
    table = BRDFTable(decode_table(be, z, c, BANDS), BANDS)
    lighting = InputLighting()
    scene = lighting.scene(SIZE)
    op = PhotoOperator(scene, BANDS, lighting.image_exposure)
    exact = op.observe(render_under(table, scene, lighting.image_exposure))
    cheap = CheapRender(OperatorSamples(op), 512, BANDS, seed=0)
    u = torch.from_numpy(lambda_coords(be.model, BANDS).numpy())
    with torch.no_grad():
        tables = be.tables.tables_of(be.model.generator(z, c), u)
        rows = cheap.rows(be.model, tables, np.arange(op.n_pixels), diffuse_floor_of(table)).numpy()
    level = float(np.percentile(exact, 99.9))
    assert rgb_psnr(exact, rows, level) > 35.0
    # a wrong exposure or a missing control variate would be far off
    assert rgb_psnr(exact, 2 * rows, level) < 15.0


@pytest.fixture(scope="module")
def made_photo(small):
    """A photo the decoder can make exactly: the table of a moved latent and colour, rendered."""
    path, image = small
    be = infer.get_backend(path, "torch")
    z0, c0 = _encoded(be, image)
    z_true = z0 + torch.from_numpy(np.random.default_rng(2).uniform(0.0, 0.6, z0.shape).astype(np.float32))
    truth = BRDFTable(decode_table(be, z_true, c0 + 0.1, BANDS), BANDS)
    lighting = InputLighting()
    return render_under(truth, lighting.scene(SIZE), lighting.image_exposure)


def test_the_fit_recovers_a_photo_the_decoder_can_make(small, made_photo):
    path, image = small
    options = LatentFitOptions(**{**FAST, "steps": 60, "refresh_every": 20})
    res = fit_latent(SphereCrop(image, True), made_photo, InputLighting(), path, BANDS, options)
    assert res.improved and res.after_db > res.before_db + 6.0, res.summary()
    assert res.table.values.shape == (90, 90, 180, BANDS.size)
    assert np.all(np.isfinite(res.table.values)) and res.table.values.min() >= 0


def test_the_held_out_half_judges_the_fit(small, made_photo):
    path, image = small
    options = LatentFitOptions(**{**FAST, "steps": 60, "refresh_every": 20, "holdout": True})
    res = fit_latent(SphereCrop(image, True), made_photo, InputLighting(), path, BANDS, options)
    assert res.improved and res.held_out_db is not None
    assert res.held_out_db[1] > res.held_out_db[0] + 6.0, res.summary()
    assert "held-out half" in res.summary()


def test_the_unresolved_peak_is_what_one_pixel_of_the_sphere_does_not_resolve():
    theta_h = grid_angles()[0]
    for size in (32, 128, 512):
        n = unresolved_theta_h_nodes(size)
        resolution = 2.0 / size                        # rad: the normal's turn over one pixel
        assert theta_h[n - 1] < resolution <= theta_h[n]
    assert unresolved_theta_h_nodes(128) == 9          # θh < 0.90°


def test_keep_peak_fits_the_body_and_returns_the_networks_peak(small, made_photo):
    path, image = small
    be = infer.get_backend(path, "torch")
    z, c = _encoded(be, image)
    network = decode_table(be, z, c, BANDS)
    options = LatentFitOptions(**{**FAST, "steps": 60, "refresh_every": 20, "keep_peak": True})
    res = fit_latent(SphereCrop(image, True), made_photo, InputLighting(), path, BANDS, options)
    n = unresolved_theta_h_nodes(SIZE)
    assert res.improved and res.after_db > res.before_db + 3.0, res.summary()
    assert np.array_equal(res.table.values[:n], network[:n])
    assert not np.allclose(res.table.values[n:], network[n:], rtol=1e-3)
    assert f"below {n}" in res.table.metadata["latent_fit"]


def test_the_same_seed_gives_the_same_table(small, made_photo):
    path, image = small
    runs = [fit_latent(SphereCrop(image, True), made_photo, None, path, BANDS, LatentFitOptions(**FAST))
            for _ in range(2)]
    assert all(r.improved for r in runs)           # the fitted tables, not the network's kept one
    assert np.array_equal(runs[0].table.values, runs[1].table.values)
    other = fit_latent(SphereCrop(image, True), made_photo, None, path, BANDS,
                       LatentFitOptions(**{**FAST, "seed": 1}))
    assert not np.array_equal(other.table.values, runs[0].table.values)


def test_a_fit_that_reproduces_the_photo_worse_keeps_the_networks_table(small):
    """The photo is the measurement: with a step size that overshoots every time, no latent the fit
    reaches reproduces the photo better, and the network's own table comes back."""
    path, image = small
    be = infer.get_backend(path, "torch")
    z0, c0 = _encoded(be, image)
    network = BRDFTable(decode_table(be, z0, c0, BANDS), BANDS)
    lighting = InputLighting()
    photo = render_under(network, lighting.scene(SIZE), lighting.image_exposure)    # the network's own
    res = fit_latent(SphereCrop(image, True), photo, lighting, path, BANDS,
                     LatentFitOptions(**{**FAST, "lr": 1.0, "steps": 6}))
    assert not res.improved and res.best_step == 0 and res.after_db == res.before_db
    assert np.array_equal(res.table.values, network.values)
    assert "kept" in res.summary()


def test_the_pipeline_refuses_the_fit_without_torch_before_any_work(small):
    from specgen_addon.generate.pipeline import generate

    path, image = small
    with pytest.raises(SpecGenError, match="torch backend"):
        generate(image, weights=path, backend="onnx", latent_fit=True)
    with pytest.raises(SpecGenError, match="does not apply"):
        generate(image, model="thin-film", latent_fit=True)


def test_cancel_stops_the_fit(small):
    path, image = small
    calls = []

    def cancel() -> bool:
        calls.append(1)
        return len(calls) > 3

    with pytest.raises(Cancelled):
        fit_latent(SphereCrop(image, True), image.astype(np.float64), None, path, BANDS,
                   LatentFitOptions(**FAST), cancel=cancel)


@pytest.mark.parametrize("bad", [dict(steps=0), dict(steps=2.5), dict(lr=0.0), dict(lr=float("nan")),
                                 dict(batch_pixels=4), dict(env_samples=0), dict(refresh_every=True),
                                 dict(eps_fraction=2.0), dict(fit_wavelengths_nm=(500.0,)),
                                 dict(fit_wavelengths_nm=(600.0, 500.0)), dict(seed=-1), dict(holdout="yes"),
                                 dict(keep_peak=1)])
def test_bad_settings_are_refused(bad):
    with pytest.raises(SpecGenError, match="latent fit"):
        LatentFitOptions(**bad)


def test_a_bad_photo_is_refused_before_any_work(small):
    path, image = small
    with pytest.raises(SpecGenError, match="square"):
        fit_latent(SphereCrop(image, True), image[:, :20], None, path, BANDS)
    bad = image.astype(np.float64).copy()
    bad[3, 3, 1] = np.nan
    with pytest.raises(SpecGenError, match="NaN"):
        fit_latent(SphereCrop(image, True), bad, None, path, BANDS)


def test_the_cli_refuses_the_fit_with_onnx_in_one_sentence(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "t.npz"
    res = subprocess.run([sys.executable, "-m", "specgen_addon", "infer", "examples/sphere.png", "-o", str(out),
                          "--latent-fit", "--backend", "onnx", "--quiet"], cwd=repo, capture_output=True,
                         text=True, timeout=600)
    assert res.returncode != 0 and not out.exists()
    assert "torch backend" in res.stderr and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_the_draw_takes_every_light_sample_and_map_samples_of_the_same_pixel():
    lighting = InputLighting()
    op = PhotoOperator(lighting.scene(SIZE), BANDS, lighting.image_exposure)
    samples = OperatorSamples(op)
    light_total = sum(g.pixel.size for g in op.groups if g.radiance_basis.shape[0] == 1)
    idx, pixel, weight = samples.draw(4, np.random.default_rng(0))
    assert np.array_equal(samples.pixel[idx], pixel)                 # each sample belongs to its pixel
    light_idx = idx[:light_total]                                     # the draw lists the lights first
    assert np.unique(light_idx).size == light_total and np.all(weight[:light_total] == 1.0)
    lights = np.concatenate([np.arange(samples.start[p], samples.env_start[p]) for p in range(op.n_pixels)])
    assert np.array_equal(np.sort(light_idx), lights)               # every light sample, once
    env = idx[light_total:]
    assert np.all(env >= samples.env_start[pixel[light_total:]])     # drawn from the pixel's map run
    np.testing.assert_allclose(np.bincount(pixel[light_total:], weight[light_total:], op.n_pixels),
                               samples.n_env)                        # they stand for all of them
