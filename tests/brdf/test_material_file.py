"""The compact material file: a generated material in a few megabytes, read back like a table,
rendering as the full table does; ``infer`` writes it by default and says what it wrote."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.render import metrics
from specgen_addon.common.errors import BRDFFormatError
from specgen_addon.evaluation.protocol import DISTANT_LIGHTS
from specgen_addon.brdf.material_file import LOG_STEP
from specgen_addon.render import Scene, sphere_geometry
from specgen_addon.brdf.table import GRID_SHAPE, BRDFTable

REPO = Path(__file__).resolve().parents[2]
#: The targets a material file is held to: size on disk, rebuild time, rendered difference.
MAX_BYTES = 10_000_000
MAX_REBUILD_S = 3.0
MIN_RENDER_DB = 60.0


def _smooth_table(rng: np.random.Generator, bands: int = 4) -> BRDFTable:
    th, td, pd = np.meshgrid(*(np.linspace(0, 1, n) for n in GRID_SHAPE), indexing="ij")
    base = np.exp(-8 * th) * 50 + 0.1 * (1 + td) + 0.01 * np.cos(2 * np.pi * pd)
    values = base[..., None] * rng.uniform(0.5, 1.5, bands)
    values[0, 0, :5] = 0.0                                  # exact zeros stay zeros
    values[1, 1, :3] = 3e-12                                # below the floor
    return BRDFTable(values, np.linspace(400, 700, bands), metadata={"description": "smooth"})


def test_a_compact_file_keeps_every_value_to_its_relative_step_and_zeros_exactly(tmp_path):
    table = _smooth_table(np.random.default_rng(0))
    path = table.save(tmp_path / "m.npz", compact=True)
    back = BRDFTable.load(path)
    pos = table.values > 1e-9
    rel = np.abs(back.values[pos] / table.values[pos] - 1)
    assert rel.max() <= np.expm1(LOG_STEP / 2) * 1.001
    assert np.all(back.values[0, 0, :5] == 0)
    assert np.all(back.values[1, 1, :3] <= 1e-9 * (1 + LOG_STEP))      # raised to the floor
    assert np.array_equal(back.wavelengths, table.wavelengths) and back.channels == table.channels
    assert back.metadata == table.metadata
    assert path.stat().st_size < table.values.nbytes / 10


def test_an_rgb_table_travels_compactly_too(tmp_path):
    table = BRDFTable(_smooth_table(np.random.default_rng(1), bands=3).values, None)
    back = BRDFTable.load(table.save(tmp_path / "rgb.npz", compact=True))
    assert back.channels == ("R", "G", "B") and back.wavelengths is None
    np.testing.assert_allclose(back.values, table.values, rtol=2e-3, atol=1e-9)


def test_a_damaged_compact_file_is_refused_in_one_sentence(tmp_path):
    path = _smooth_table(np.random.default_rng(2)).save(tmp_path / "m.npz", compact=True)
    import zipfile

    with zipfile.ZipFile(path) as zf:
        parts = {n: zf.read(n) for n in zf.namelist()}
    codes = bytearray(parts["codes.npy"])
    codes[-200:] = bytes(200)
    parts["codes.npy"] = bytes(codes)
    bad = tmp_path / "bad.npz"
    with zipfile.ZipFile(bad, "w") as zf:
        for n, b in parts.items():
            zf.writestr(n, b)
    with pytest.raises(BRDFFormatError, match="damaged compact material"):
        BRDFTable.load(bad)


def _render(table: BRDFTable) -> tuple[np.ndarray, np.ndarray]:
    res = Scene(sphere_geometry(128), DISTANT_LIGHTS).render_spectral(table, table.wavelengths)
    return res.spectral, res.mask


@pytest.mark.slow
def test_infer_writes_a_compact_material_that_renders_as_the_full_table(tmp_path):
    """Default ``infer`` output against ``--full-table``: size, rebuild time and render."""
    image = REPO / "examples" / "sphere.png"
    outs = {}
    for name, extra in (("compact", []), ("full", ["--full-table"])):
        out = tmp_path / f"{name}.npz"
        done = subprocess.run([sys.executable, "-m", "specgen_addon", "infer", str(image), "-o", str(out),
                               "--no-refine", "--backend", "onnx", "--quiet", *extra],
                              capture_output=True, text=True, cwd=REPO, timeout=600, check=False)
        assert done.returncode == 0, done.stderr
        kind = "compact material" if name == "compact" else "full table"
        assert f"wrote {out} ({kind}, " in done.stdout and " MB)" in done.stdout, done.stdout
        outs[name] = out
    assert outs["compact"].stat().st_size <= MAX_BYTES
    t0 = time.perf_counter()
    compact = BRDFTable.load(outs["compact"])
    assert time.perf_counter() - t0 <= MAX_REBUILD_S
    full = BRDFTable.load(outs["full"])
    ref, mask = _render(full)
    got, _ = _render(compact)
    assert metrics.spectral_metrics(ref, got, mask).psnr_mean >= MIN_RENDER_DB


@pytest.mark.parametrize("axis", [0, 1, 2, 3])
def test_the_encoders_difference_is_numpys_diff_with_a_leading_zero(axis):
    from specgen_addon.brdf.material_file import _difference

    codes = np.random.default_rng(axis).integers(-3000, 3000, (5, 6, 7, 8)).astype(np.int32)
    np.testing.assert_array_equal(_difference(codes, axis), np.diff(codes, axis=axis, prepend=0))
