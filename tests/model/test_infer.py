"""Inference: the fast grid path is exact, tables come out right, bad inputs are refused."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from specgen_addon.model.runtime import inference as infer
from specgen_addon.common.errors import Cancelled, ImageInputError, SpecGenError, WeightsError
from specgen_addon.model import Config, SpecGen, save_weights
from specgen_addon.model.runtime.fast import GridHead, GridTables, lambda_coords
from specgen_addon.brdf.lookup_reach import phi_d_reach
from specgen_addon.brdf.table import grid_angles
from tiny_model import TINY_MODEL

SMALL = TINY_MODEL
BANDS = np.array([400.0, 515.0, 690.0])


@pytest.fixture(scope="module")
def sphere_image() -> np.ndarray:
    """A canonical input render (64², linear sRGB) of a closed-form spectral material."""
    from specgen_addon.photo.sphere_image import render_input
    from specgen_standins import RampMaterial

    return render_input(RampMaterial(), size=64)


def small_weights(tmp_path, **kw):
    torch.manual_seed(0)
    model = SpecGen(Config(**{**SMALL, **kw}))
    if model.cfg.fusion == "aff":  # a lively AFF statistic: softmax weights vary between points
        torch.nn.init.normal_(model.fusion.branch_convs.weight, std=0.5)
        torch.nn.init.normal_(model.fusion.expand.weight, std=2.0)
    return save_weights(model, tmp_path / f"w_{kw.get('fusion', 'aff')}.pt"), model


@pytest.mark.parametrize("fusion,knots", [("aff", 1), ("aff", 4), ("hadamard", 4)])
def test_fast_grid_equals_naive_per_query_evaluation(tmp_path, fusion, knots):
    path, model = small_weights(tmp_path, fusion=fusion, spectral_code_knots=knots)
    if knots > 1:  # knots that differ, so the spectral code really varies along the angle axes
        torch.nn.init.normal_(model.generator.spectral.weight, std=0.3)
        path = save_weights(model, path)
    be = infer.get_backend(path, "torch")
    x = np.random.default_rng(0).random((1, 3, 32, 32)).astype(np.float32)
    u_lam = lambda_coords(model, BANDS).numpy()
    rp = infer.evaluate_grid(be, be.make_tables(x, u_lam), BANDS.size)
    assert rp.shape == (90, 90, 180, 3)

    th, td, pd = grid_angles()
    lo, hi = phi_d_reach()
    idx = np.random.default_rng(1).integers(0, [90, 90, 180, 3], size=(4000, 4))
    reached = (idx[:, 2] >= lo[idx[:, 0], idx[:, 1]]) & (idx[:, 2] <= hi[idx[:, 0], idx[:, 1]])
    beyond, idx = idx[~reached], idx[reached]                 # no lookup reads the nodes beyond
    assert len(idx) > 2000 and len(beyond) > 500
    edge = np.clip(beyond[:, 2], lo[beyond[:, 0], beyond[:, 1]], hi[beyond[:, 0], beyond[:, 1]])
    assert np.array_equal(rp[beyond[:, 0], beyond[:, 1], beyond[:, 2], beyond[:, 3]],
                          rp[beyond[:, 0], beyond[:, 1], edge, beyond[:, 3]])
    q = lambda a: torch.tensor(a, dtype=torch.float32)[None]  # noqa: E731
    with torch.no_grad():
        planes = model.eval().planes(torch.from_numpy(x))
        naive = model.query(planes, q(th[idx[:, 0]]), q(td[idx[:, 1]]), q(pd[idx[:, 2]]),
                            q(BANDS[idx[:, 3]]))[0].numpy()
    fast = rp[idx[:, 0], idx[:, 1], idx[:, 2], idx[:, 3]]
    assert np.abs(fast - naive).max() < 1e-5


def test_shifted_logit_segments_give_the_logits_minus_their_maximum(tmp_path):
    from specgen_addon.model.runtime.gather import shifted_logit_segments

    _, model = small_weights(tmp_path)
    torch.nn.init.normal_(model.fusion.heads.weight, std=3.0)      # many arg-max changes
    kinks, pq = shifted_logit_segments(model.fusion)
    s = torch.linspace(-40.0, 40.0, 20001)
    with torch.no_grad():
        z = model.fusion.heads(torch.relu(model.fusion.expand(s[:, None])))     # Eq. (8)–(10) as written
    seg = pq[torch.bucketize(s, kinks)]
    shifted = seg[:, :6] * s[:, None] + seg[:, 6:]
    assert torch.allclose(shifted, z - z.max(dim=1, keepdim=True).values, atol=1e-4)
    assert shifted.max() <= 1e-4                                   # exp(·) ≤ 1: no overflow
    assert torch.all(kinks[1:] > kinks[:-1])


@pytest.fixture(params=["numba loops", "torch ops"])
def gather_path(request, monkeypatch) -> str:
    """Run a gather-head test on both of its paths: with the numba loops, and on torch ops alone."""
    from specgen_addon.model.runtime import gather_kernels

    if request.param == "torch ops":
        monkeypatch.setenv(gather_kernels.ENV_VAR, "torch")
    else:
        monkeypatch.delenv(gather_kernels.ENV_VAR, raising=False)
        if gather_kernels.load() is None:
            pytest.skip("numba is not installed (requirements.txt lists it)")
    return request.param


def test_gather_head_equals_the_exportable_head(tmp_path, gather_path):
    from specgen_addon.model.runtime.gather import GatherGridHead

    _, model = small_weights(tmp_path)
    with torch.no_grad():
        tables = GridTables(model)(torch.rand(1, 3, 32, 32), lambda_coords(model, BANDS))
    head = GridHead(model)
    gather = GatherGridHead(model, tables, 7)                      # 90 = 12 × 7 + 6: a short last block
    assert (gather.kernels is not None) == (gather_path == "numba loops")
    for i, j in ((0, 0), (3, 14), (89, 84)):
        nd = min(7, 90 - j)
        blocks = (tables[0][i:i + 1, j:j + nd], tables[1][i:i + 1], tables[2][j:j + nd],
                  tables[3][i:i + 1], tables[4][j:j + nd], tables[5])
        with torch.no_grad():
            a = head(*blocks).numpy()
        b = gather.block(i, j)
        assert b.shape == a.shape == (1, nd, 180, 3)
        reached = _reached(i, j, nd)
        assert np.allclose(a[reached], b[reached], atol=1e-5)


def test_gather_head_drops_units_that_are_dead_everywhere_and_gives_the_same_values(tmp_path, gather_path):
    from specgen_addon.model.runtime.gather import GatherGridHead

    _, model = small_weights(tmp_path)
    with torch.no_grad():
        model.mapping.fc1.bias[:5] = -1e3                          # five units that never fire
        tables = GridTables(model)(torch.rand(1, 3, 32, 32), lambda_coords(model, BANDS))
    gather = GatherGridHead(model, tables, 10)
    assert gather.units_dropped == 5
    blocks = (tables[0][7:8, 20:30], tables[1][7:8], tables[2][20:30], tables[3][7:8], tables[4][20:30],
              tables[5])
    with torch.no_grad():
        want = GridHead(model)(*blocks).numpy()
    reached = _reached(7, 20, 10)
    assert np.allclose(want[reached], gather.block(7, 20)[reached], atol=1e-5)


def _reached(i: int, j: int, nd: int) -> np.ndarray:
    """(1, nd, 180, Λ) mask of the nodes a lookup can touch in θh row i, θd rows j … j + nd."""
    lo, hi = (a[i, j:j + nd, None] for a in phi_d_reach())
    p = np.arange(180)
    return np.broadcast_to(((p >= lo) & (p <= hi))[None, :, :, None], (1, nd, 180, BANDS.size))


def test_gather_head_computes_only_the_lookups_reach_and_decodes_it(tmp_path, gather_path):
    from specgen_addon.model.runtime.gather import GatherGridHead
    from specgen_addon.brdf.table import mu_law_decode

    _, model = small_weights(tmp_path)
    with torch.no_grad():
        tables = GridTables(model)(torch.rand(1, 3, 32, 32), lambda_coords(model, BANDS))
    gather = GatherGridHead(model, tables, 10)
    lo, hi = gather.reach(89, 80)
    assert np.array_equal(lo, phi_d_reach()[0][89, 80:90]) and np.all(hi - lo < 40)
    rp, fr = gather.block(89, 80), gather.block(89, 80, decode_mu=model.cfg.mu)
    reached = _reached(89, 80, 10)
    assert reached.mean() < 0.25                                  # grazing rows: most of φd is never read
    np.testing.assert_allclose(fr[reached], mu_law_decode(np.clip(rp[reached], 0, None), model.cfg.mu),
                               rtol=1e-6, atol=1e-9)


def test_numba_logit_loop_equals_bucketize_and_the_segment_rows(tmp_path):
    from specgen_addon.model.runtime import gather_kernels
    from specgen_addon.model.runtime.gather import shifted_logit_segments

    kernels = gather_kernels.load()
    if kernels is None:
        pytest.skip("numba is not installed (requirements.txt lists it), or SPECGEN_KERNELS=torch")
    _, model = small_weights(tmp_path)
    torch.nn.init.normal_(model.fusion.heads.weight, std=3.0)      # many arg-max changes: many kinks
    kinks, pq = shifted_logit_segments(model.fusion)
    assert kinks.numel() > 8
    rng = np.random.default_rng(3)
    lo, hi = float(kinks[0]) - 2.0, float(kinks[-1]) + 2.0
    stats = [rng.uniform(lo / 7, hi / 7, shape).astype(np.float32)
             for shape in ((90, 90), (90, 180), (90, 180), (90, 3), (90, 3), (180, 3))]
    s1, s2, s3, s4, s5, s6 = stats
    i, j, nd, bias = 4, 85, 5, np.float32(0.25)
    lo, hi = np.array([0, 3, 50, 90, 0]), np.array([179, 170, 130, 90, 10])     # each row's φd run
    out = np.empty((int((hi - lo + 1).sum()) * 3, 6), np.float32)
    kernels.shifted_logits(i, j, nd, lo, hi, *stats, bias, kinks.numpy(), pq.numpy(), out)
    d, p, lam = (np.concatenate(a) for a in zip(*(
        (np.full(3 * (b - a + 1), j + r), np.repeat(np.arange(a, b + 1), 3), np.tile(np.arange(3), b - a + 1))
        for r, (a, b) in enumerate(zip(lo, hi)))))
    s = torch.from_numpy(((s1[i, d] + s2[i, p] + s3[d, p] + bias) + s4[i, lam] + s5[d, lam] + s6[p, lam])
                         .astype(np.float32))
    seg = pq[torch.bucketize(s, kinks)]
    assert np.allclose(out, (seg[:, :6] * s[:, None] + seg[:, 6:]).numpy(), atol=1e-5)
    assert out.max() <= 1e-5                                        # exp(·) ≤ 1, as the torch path


def test_numba_gather_and_output_loops_equal_embedding_bag_and_the_last_layer():
    from specgen_addon.model.runtime import gather_kernels

    kernels = gather_kernels.load()
    if kernels is None:
        pytest.skip("numba is not installed (requirements.txt lists it), or SPECGEN_KERNELS=torch")
    rng = np.random.default_rng(5)
    # a small grid: 5 θd rows, 7 φd nodes, 3 bands; the row table t3 | t5 | t6 | t1[i] | t2[i] | t4[i]
    n_d, n_phi, n_l, j, nd = 5, 7, 3, 2, 3
    offsets = np.cumsum([0, n_d * n_phi, n_d * n_l, n_phi * n_l, n_d, n_phi])      # o3, o5, o6, o1, o2, o4
    o3, o5, o6, o1, o2, o4 = offsets
    rows = rng.normal(size=(o4 + n_l, 11)).astype(np.float32)
    rows[:, -1] = 1.0                                               # the trailing column: Σ e
    lo, hi = np.array([0, 2, 3]), np.array([6, 4, 3])               # each θd row's φd run
    indices = np.array([[o1 + d, o2 + p, o3 + d * n_phi + p, o4 + lam, o5 + d * n_l + lam, o6 + p * n_l + lam]
                        for r in range(nd) for d in [j + r] for p in range(lo[r], hi[r] + 1)
                        for lam in range(n_l)], dtype=np.int64)
    n = len(indices)
    e = rng.uniform(0.0, 1.0, size=(n, 6)).astype(np.float32)
    h, t = np.empty((n, 11), np.float32), np.empty(n, np.float32)
    order = np.array([o1, o2, o3, o4, o5, o6], dtype=np.int64)
    kernels.gather_relu(j, nd, lo, hi, n_phi, n_l, order, rows, e, h, t)
    want = torch.nn.functional.embedding_bag(torch.from_numpy(indices), torch.from_numpy(rows),
                                             per_sample_weights=torch.from_numpy(e), mode="sum").relu()
    assert np.allclose(h, want.numpy(), atol=1e-5)
    assert np.array_equal(t, h[:, -1])
    g = rng.normal(size=(n, 9)).astype(np.float32)
    w3, b3 = rng.normal(size=9).astype(np.float32), np.float32(-0.5)
    r = np.empty(n, np.float32)
    kernels.mlp_output(g, t, w3, b3, r)
    assert np.allclose(r, np.maximum(g, 0.0) @ w3 / t + b3, rtol=1e-5, atol=1e-5)
    # a NaN (an overflow upstream) survives both ReLUs, as it does torch's, so limits.bad_values sees it
    rows[indices[3, 2], 4], g[7, 5] = np.nan, np.nan
    kernels.gather_relu(j, nd, lo, hi, n_phi, n_l, order, rows, e, h, t)
    want = torch.nn.functional.embedding_bag(torch.from_numpy(indices), torch.from_numpy(rows),
                                             per_sample_weights=torch.from_numpy(e), mode="sum").relu()
    assert np.array_equal(np.isnan(h), np.isnan(want.numpy())) and np.isnan(h[3, 4])
    kernels.mlp_output(g, t, w3, b3, r)
    assert np.isnan(r[7]) and np.isfinite(np.delete(r, 7)).all()


_CALL_THE_LOOPS = """
import importlib.util, sys
import numpy as np
REPO, PACKAGE = sys.argv[1], sys.argv[2]
if PACKAGE != "specgen_addon":       # the core under another package name, as the add-on loads it
    spec = importlib.util.spec_from_file_location(PACKAGE, REPO + "/specgen_addon/__init__.py",
                                                  submodule_search_locations=[REPO + "/specgen_addon"])
    sys.modules[PACKAGE] = module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
else:
    sys.path.insert(0, REPO)
kernels = importlib.import_module(PACKAGE + ".model.runtime.gather_kernels").load()
f = np.float32
stats = [np.zeros(shape, f) for shape in ((90, 90), (90, 180), (90, 180), (90, 2), (90, 2), (180, 2))]
e = np.empty((180 * 2, 6), f)
lo, hi = np.zeros(1, np.int64), np.full(1, 179, np.int64)
kernels.shifted_logits(0, 0, 1, lo, hi, *stats, f(0), np.zeros(1, f), np.zeros((2, 12), f), e)
h, t = np.empty((360, 3), f), np.empty(360, f)
kernels.gather_relu(0, 1, lo, hi, 180, 2, np.zeros(6, np.int64), np.ones((2000, 3), f), np.exp(e), h, t)
r = np.empty(360, f)
kernels.mlp_output(np.ones((360, 4), f), t, np.ones(4, f), f(0), r)
assert np.allclose(r, 4.0 / 6.0), r[:3]
print("ok")
"""


@pytest.mark.slow
def test_numba_cache_written_under_the_add_on_package_serves_the_command_line(tmp_path):
    """numba's on-disk cache records each function's module name: a cache written while the core
    was loaded under the add-on's package name must still load in a plain ``specgen_addon``."""
    import subprocess
    import sys
    from pathlib import Path

    from specgen_addon.model.runtime import gather_kernels

    if gather_kernels.load() is None:
        pytest.skip("numba is not installed (requirements.txt lists it), or SPECGEN_KERNELS=torch")
    repo = str(Path(__file__).resolve().parents[2])
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    for package in ("specgen_as_add_on", "specgen_addon", "specgen_as_add_on"):
        res = subprocess.run([sys.executable, "-c", _CALL_THE_LOOPS, repo, package], env=env,
                             capture_output=True, text=True, timeout=300)
        assert res.returncode == 0 and res.stdout.strip() == "ok", (package, res.stderr[-2000:])
    assert any((tmp_path / "numba").rglob("*.nbi"))                # the cache was written and reused


def test_kernels_switch_off_with_the_environment_variable(monkeypatch):
    from specgen_addon.model.runtime import gather_kernels

    monkeypatch.setenv(gather_kernels.ENV_VAR, "torch")
    assert gather_kernels.load() is None


def test_grid_decoded_on_the_workers_equals_the_decoded_grid(tmp_path):
    from specgen_addon.brdf.table import mu_law_decode

    path, model = small_weights(tmp_path)
    be = infer.get_backend(path, "torch")
    x = np.random.default_rng(0).random((1, 3, 32, 32)).astype(np.float32)
    tables = be.make_tables(x, lambda_coords(model, BANDS).numpy())
    rp = infer.evaluate_grid(be, tables, BANDS.size)
    fr = infer.evaluate_grid(be, tables, BANDS.size, decode_mu=model.cfg.mu)
    np.testing.assert_allclose(fr, mu_law_decode(np.clip(rp, 0, None), model.cfg.mu), rtol=1e-6, atol=1e-9)


def test_generate_brdf_writes_a_full_spectral_table(tmp_path, sphere_image):
    path, _ = small_weights(tmp_path)
    ticks = []
    table = infer.generate_brdf(sphere_image, weights=path, wavelengths_nm=BANDS, progress=ticks.append)
    assert table.values.shape == (90, 90, 180, 3) and table.is_spectral
    assert np.array_equal(table.wavelengths, BANDS)
    assert np.all(table.values >= 0) and np.all(np.isfinite(table.values))
    assert ticks[-1] == pytest.approx(1.0) and ticks == sorted(ticks)
    out = table.save(tmp_path / "brdf.npz")
    assert out.is_file()


def test_generate_brdf_can_be_cancelled(tmp_path, sphere_image):
    path, _ = small_weights(tmp_path)
    with pytest.raises(Cancelled):
        infer.generate_brdf(sphere_image, weights=path, wavelengths_nm=BANDS, cancel=lambda: True)


def test_wavelengths_outside_the_model_range_are_refused(tmp_path, sphere_image):
    path, _ = small_weights(tmp_path)
    with pytest.raises(SpecGenError, match="outside the model's 380–780 nm"):
        infer.generate_brdf(sphere_image, weights=path, wavelengths_nm=[350.0, 500.0])


def test_images_without_a_sphere_or_with_wrong_channels_are_refused(tmp_path):
    path, _ = small_weights(tmp_path)
    with pytest.raises(ImageInputError):
        infer.generate_brdf(np.zeros((64, 64, 3), np.float32), weights=path)
    with pytest.raises(ImageInputError):
        infer.generate_brdf(np.ones((64, 64, 2), np.float32), weights=path)
    with pytest.raises(ImageInputError):
        infer.generate_brdf(np.full((64, 64, 3), np.nan, np.float32), weights=path)


def test_bad_weights_file_gives_a_weights_error(tmp_path, sphere_image):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00" * 100)
    with pytest.raises(WeightsError, match="bad.pt"):
        infer.generate_brdf(sphere_image, weights=bad)
    with pytest.raises(WeightsError, match="not found"):
        infer.generate_brdf(sphere_image, weights=tmp_path / "none.pt")


def test_shipped_default_weights_load():
    from specgen_addon.model import DEFAULT_WEIGHTS, load_weights

    model = load_weights()
    assert DEFAULT_WEIGHTS.stat().st_size < 20e6
    assert model.meta.get("steps", 0) > 0
