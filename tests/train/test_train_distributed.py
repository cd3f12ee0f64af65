"""Distributed training (torchrun + DDP): sharding, world size 1, two ranks vs one process."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.distributed as dist

from specgen_addon.common.errors import SpecGenError
from specgen_addon.model import Config, load_weights
from specgen_addon.train import distributed as ddp
from specgen_addon.train.data import make_batch
from specgen_addon.train.loop import TrainConfig, train
from tiny_training import FAST_TRAIN as FAST, TRAIN_MODEL as SMALL, material_sets as sets

HERE = Path(__file__).resolve().parents[1]


def _batch(n: int):
    spec, _, _ = sets(n)
    return make_batch(spec.materials, [im[0] for im in spec.images], np.random.default_rng(3), 64, 4, True,
                      np.linspace(380, 780, 41))


@pytest.mark.parametrize("world", [2, 3])
def test_shards_are_disjoint_and_their_weighted_losses_average_to_the_batch_loss(world):
    b = _batch(5)
    b.valid[1, :40] = False                       # shards with different valid counts
    err = np.random.default_rng(0).random(b.target.shape)
    whole = (err * b.valid).sum() / b.valid.sum()
    rows, shares, tv_w = [], [], []
    for rank in range(world):
        part, w_mse, w_tv = ddp.shard(b, ddp.DistContext(rank, world, True))
        first = next(i for i in range(5) if np.array_equal(b.images[i], part.images[0]))
        rows += list(range(first, first + part.images.shape[0]))
        e = err[first:first + part.images.shape[0]]
        shares.append(w_mse * (e * part.valid).sum() / part.valid.sum())
        tv_w.append(w_tv)
        assert np.array_equal(part.target, b.target[first:first + part.images.shape[0]])
    assert sorted(rows) == list(range(5))             # disjoint, and together the whole batch
    assert np.isclose(np.mean(shares), whole, rtol=1e-12)
    assert np.isclose(np.mean(tv_w), 1.0)


@pytest.mark.parametrize("world", [2, 3])
def test_a_rank_evaluating_only_its_own_targets_gets_the_same_shard(world):
    spec, _, _ = sets(5)
    whole = _batch(5)
    for rank in range(world):
        ctx = ddp.DistContext(rank, world, True)
        lean = make_batch(spec.materials, [im[0] for im in spec.images], np.random.default_rng(3), 64, 4,
                          True, np.linspace(380, 780, 41), evaluate=ddp.shard_rows(5, ctx))
        a, b = ddp.shard(whole, ctx), ddp.shard(lean, ctx)
        for name in ("target", "valid", "theta_h", "theta_d", "phi_d", "wavelength_nm", "images"):
            assert np.array_equal(getattr(a[0], name), getattr(b[0], name)), name
        assert a[1:] == b[1:]


def test_more_ranks_than_materials_per_step_is_refused():
    with pytest.raises(SpecGenError, match="rgb_materials_per_step = 1 cannot be shared by 2 ranks"):
        ddp.check_shardable({"spectral_materials_per_step": 4, "rgb_materials_per_step": 1},
                            ddp.DistContext(0, 2, True))
    ddp.check_shardable({"spectral_materials_per_step": 2, "rgb_materials_per_step": 0},
                        ddp.DistContext(1, 2, True))


def test_ddp_with_world_size_one_equals_plain_training_bit_for_bit(tmp_path):
    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 3})
    plain = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "plain", show_progress=False)
    dist.init_process_group("gloo", init_method=f"file://{tmp_path / 'store'}", rank=0, world_size=1)
    try:
        assert ddp.context() == ddp.DistContext(0, 1, True)
        one = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "ddp", show_progress=False)
    finally:
        ddp.shutdown()
    a, b = (load_weights(r.weights).state_dict() for r in (plain, one))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [r["loss"] for r in plain.history] == [r["loss"] for r in one.history]


@pytest.mark.slow
def test_torchrun_two_ranks_match_one_process_and_resume_exactly(tmp_path):
    """Same global batch: 2 DDP ranks (gloo) ≈ 1 process; rank 0 alone writes; resume is exact."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    script = str(HERE / "ddp_tiny_run.py")
    for cmd, out in (([sys.executable, script], "single"),
                     ([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                       script], "ddp")):
        done = subprocess.run(cmd + [str(tmp_path / out)], capture_output=True, text=True, env=env,
                              timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
    w = {k: load_weights(tmp_path / k / "rank0" / "full" / "specgen.pt").state_dict() for k in ("single", "ddp")}
    resumed = load_weights(tmp_path / "ddp" / "rank0" / "resumed" / "specgen.pt").state_dict()
    for k in w["single"]:
        torch.testing.assert_close(w["ddp"][k], w["single"][k], rtol=1e-5, atol=1e-6)
        assert torch.equal(resumed[k], w["ddp"][k]), k
    hist = [np.genfromtxt(tmp_path / k / "rank0" / "full" / "history.csv", delimiter=",", names=True)
            for k in ("single", "ddp")]
    np.testing.assert_allclose(hist[1]["loss"], hist[0]["loss"], rtol=1e-6)
    assert not [p for p in (tmp_path / "ddp" / "rank1").rglob("*") if p.is_file()]  # rank 0 alone writes


def test_the_backend_follows_the_training_device():
    assert ddp.backend(torch.device("cpu")) == "gloo"
    assert ddp.backend(torch.device("cuda", 0)) == "nccl"
    assert ddp.train_device("cpu") == torch.device("cpu")
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert ddp.train_device("auto").type == expected


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without a GPU")
def test_asking_for_cuda_without_a_gpu_is_refused_before_any_work(tmp_path):
    with pytest.raises(SpecGenError, match="no CUDA GPU"):
        ddp.train_device("cuda")
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "train", "--out", str(tmp_path / "run"),
                        "--device", "cuda", "--steps", "1"], capture_output=True, text=True,
                       cwd=HERE.parent, timeout=120)
    assert r.returncode == 2 and "no CUDA GPU" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "run").exists()


def test_an_unknown_training_device_is_a_config_error():
    with pytest.raises(SpecGenError, match="device must be"):
        TrainConfig.from_dict({"device": "tpu"})


def test_training_on_auto_here_is_training_on_the_cpu_bit_for_bit(tmp_path):
    """No GPU: "auto" must fall back to the CPU and change nothing (same weights, bit for bit)."""
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU: auto trains there")
    spec, rgb, val = sets(4)
    base = TrainConfig(**{**FAST, "steps": 3})
    a = train(Config(**SMALL), base, spec, rgb, val, tmp_path / "cpu", show_progress=False)
    b = train(Config(**SMALL), TrainConfig(**{**FAST, "steps": 3, "device": "auto"}), spec, rgb, val, tmp_path / "auto",
              show_progress=False)
    wa, wb = load_weights(a.weights).state_dict(), load_weights(b.weights).state_dict()
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
