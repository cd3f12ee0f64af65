"""Ablation arms trained elsewhere (a lent GPU) under the keys `ablate` looks up, and their trip back."""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import tarfile
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.evaluation import ablation as abl
from specgen_addon.evaluation.ablation_study import study_settings

REPO = Path(__file__).resolve().parents[2]


def _gpu_ablate():
    spec = importlib.util.spec_from_file_location("gpu_ablate", REPO / "lab" / "gpu" / "gpu_ablate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_train_arms_refuses_an_override_that_would_change_what_an_arm_is(tmp_path):
    settings = study_settings(6000, [6], ["joint-aff"])
    with pytest.raises(ValueError, match="lr"):
        abl.train_arms(settings, tmp_path, log=lambda s: None, run_overrides={"device": "cpu", "lr": 0.1})
    assert list(tmp_path.iterdir()) == []


def _fake_arms(cache: Path, settings: abl.AblationSettings) -> dict[str, dict[str, bytes]]:
    rng = np.random.default_rng(0)
    made = {}
    for seed in settings.seeds:
        for arm in settings.arms:
            key = settings.key(abl.ARMS_BY_NAME[arm], seed)
            (cache / key).mkdir(parents=True)
            made[key] = {"specgen.pt": rng.bytes(300_000), "history.csv": b"step,loss\n1,0.5\n",
                         "arm.json": b'{"seed": %d, "steps": 6000, "wall_seconds": 1.0}' % seed}
            for name, data in made[key].items():
                (cache / key / name).write_bytes(data)
    return made


def _args(mod, *argv: str):
    return mod.main(list(argv))


def test_packed_arms_come_back_byte_for_byte_and_a_cut_tar_gives_only_whole_arms(tmp_path):
    mod = _gpu_ablate()
    there, here = tmp_path / "there", tmp_path / "here"
    settings = study_settings(6000, [6, 8], ["joint-aff", "joint-hadamard"])
    made = _fake_arms(there, settings)
    tar = tmp_path / "arms.tar"
    common = ["--steps", "6000", "--seeds", "6", "8", "--arms", "joint-aff", "joint-hadamard"]
    assert _args(mod, *common, "--cache", str(there), "--pack", str(tar)) == 0
    again = tmp_path / "again.tar"
    _args(mod, *common, "--cache", str(there), "--pack", str(again))
    assert tar.read_bytes() == again.read_bytes()  # the same arms give the same bytes (chunks match)

    cut = tmp_path / "cut.tar"
    cut.write_bytes(tar.read_bytes()[: int(tar.stat().st_size * 0.6)])
    assert _args(mod, "--cache", str(here), "--unpack", str(cut)) == 0
    whole = sorted(p.name for p in here.iterdir())
    assert 0 < len(whole) < len(made)
    for key in whole:
        assert {p.name: p.read_bytes() for p in (here / key).iterdir()} == made[key]

    assert _args(mod, "--cache", str(here), "--unpack", str(tar)) == 0
    assert sorted(p.name for p in here.iterdir()) == sorted(made)
    for key, files in made.items():
        assert {p.name: p.read_bytes() for p in (here / key).iterdir()} == files


def test_unpack_refuses_a_tar_with_anything_but_arm_files(tmp_path):
    mod = _gpu_ablate()
    bad = tmp_path / "bad.tar"
    (tmp_path / "x.sh").write_text("echo")
    with tarfile.open(bad, "w") as t:
        t.add(tmp_path / "x.sh", arcname="../evil/specgen.pt")
    with pytest.raises(SystemExit, match="not an arm's file"):
        _args(mod, "--cache", str(tmp_path / "c"), "--unpack", str(bad))
    assert not (tmp_path / "c").exists() and not (tmp_path.parent / "evil").exists()


@pytest.mark.slow
def test_an_arm_stopped_by_its_time_limit_is_not_complete_until_a_later_run_finishes_it(tmp_path, monkeypatch):
    """A per-call stop leaves the arm resumable and unscored; the next call finishes it under the
    same key, so `ablate` then finds it (the lent-GPU path of docs/ablations.md)."""
    monkeypatch.setenv("SPECGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setitem(os.environ, "OMP_NUM_THREADS", "1")
    base = study_settings(4, [3], ["joint-hadamard"])
    settings = dataclasses.replace(base, train={**base.train, **abl.SMOKE_TRAIN})
    arms = tmp_path / "arms"
    stopped = abl.train_arms(settings, arms, progress=False, log=lambda s: None,
                             run_overrides={"max_minutes": 1e-6, "render_workers": 1})
    assert stopped == {}
    key = settings.key(abl.ARMS_BY_NAME["joint-hadamard"], 3)
    assert (arms / key / "checkpoint.pt").is_file() and not (arms / key / "arm.json").exists()
    done = abl.train_arms(settings, arms, progress=False, log=lambda s: None)
    assert done["joint-hadamard/seed3"].steps == 4 and (arms / key / "arm.json").is_file()
