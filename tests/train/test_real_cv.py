"""Cross-validation over the real files: folds partition the files, a fold never trains on its own."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from specgen_addon.evaluation.real_files import summarise
from specgen_addon.train import real_rgb
from specgen_addon.train.data import TrainingMaterial
from specgen_addon.train.loop import TrainConfig
from script_modules import load_script

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def real_cv():
    return load_script("bench/real_cv.py")


@pytest.fixture
def folder(tmp_path):
    for i in range(14):
        (tmp_path / f"m{i:02d}_rgb.bsdf").write_bytes(b"x")
    return tmp_path


def test_folds_hold_every_file_exactly_once(real_cv, folder):
    files = sorted(folder.glob("*.bsdf"))
    folds = real_cv.folds_of(files, 7, seed=0)
    assert [len(f) for f in folds] == [2] * 7
    assert sorted(p for f in folds for p in f) == files
    assert real_cv.folds_of(files, 7, seed=0) == folds
    assert real_cv.folds_of(files, 7, seed=1) != folds


def test_a_fold_never_trains_on_its_held_out_files(real_cv, folder, monkeypatch):
    """The real source a fold's config builds holds every file but the fold's own."""
    loaded: list[list[str]] = []

    def fake_load(files, cache_dir, progress=None):
        loaded.append([p.stem for p in files])
        return [TrainingMaterial(p.stem, object(), False) for p in files]

    monkeypatch.setattr(real_rgb, "load_file_materials", fake_load)
    monkeypatch.setattr(real_rgb, "canonical_photo", lambda p, c, log=None: np.zeros((4, 4, 3), np.float32))
    files = sorted(folder.glob("*.bsdf"))
    for held in real_cv.folds_of(files, 7, seed=0):
        names = [p.stem for p in held]
        tcfg = TrainConfig(real_materials_per_step=2, real_rgb_dir=str(folder), real_exclude=names)
        src = real_rgb.real_source(tcfg, folder / "cache", log=lambda _m: None)
        assert not set(src.names) & set(names)
        assert len(src) == len(files) - len(names) and loaded[-1] == src.names


def test_no_real_source_without_real_materials(folder):
    assert real_rgb.real_source(TrainConfig(real_rgb_dir=str(folder)), folder) is None


def test_summary_gives_mean_and_worst_file():
    rows = [{"material": "a", "psnr_distant": 20.0}, {"material": "b", "psnr_distant": 30.0}]
    s = summarise(rows)
    assert s["psnr_distant"] == {"mean": 25.0, "min": 20.0, "min_file": "a"} and s["n"] == 2
