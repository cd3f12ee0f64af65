"""``ablate`` with its default two workers: each arm trains in a pool worker (a daemonic process,
which may not start processes), so the training renders are made before the pool starts and an
arm's own render step runs in-process. Checked under each start method SpecGen may use."""

from __future__ import annotations

import multiprocessing as mp

import pytest

from specgen_addon.evaluation import ablation as abl
from specgen_addon.evaluation import ablation_study as study
from specgen_addon.common.processes import ENV_START_METHOD

START_METHODS = [m for m in ("fork", "spawn") if m in mp.get_all_start_methods()]


@pytest.mark.slow
@pytest.mark.parametrize("method", START_METHODS)
def test_a_tiny_two_worker_ablation_trains_and_scores_both_arms(method, tmp_path, monkeypatch):
    monkeypatch.setenv("SPECGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv(ENV_START_METHOD, method)
    model, train = abl._default_configs()
    tiny = {**train, **abl.SMOKE_TRAIN, "corpus_size": 6, "render_workers": 2}
    monkeypatch.setattr(abl, "_default_configs", lambda: (model, tiny))
    lines: list[str] = []
    res = study.run_study(2, seeds=[0], arms=["joint-aff", "joint-hadamard"], workers=2, per_family=1,
                          resolution=16, cache_dir=tmp_path / "arms", log=lines.append)
    assert sorted(r["arm"] for r in res["records"]) == ["joint-aff", "joint-hadamard"]
    assert all(r["steps"] == 2 for r in res["records"])
    assert len([ln for ln in lines if ln.startswith("ablate:")]) == 2
