"""Training: targets as the paper defines them, overfitting, determinism, resume, configs."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from specgen_addon.common.errors import SpecGenError
from specgen_addon.model import Config, load_weights
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
from specgen_addon.brdf.table import mu_law_encode
from specgen_addon.train.data import TrainingMaterial, make_batch, material_targets, sample_angles
from specgen_addon.train.loop import MaterialSet, TrainConfig, load_config, lr_at, train
from tiny_training import FAST_TRAIN as FAST, TRAIN_MODEL as SMALL, material_sets as sets
from specgen_standins import RampMaterial

def test_spectral_targets_are_mu_law_of_the_brdf():
    mat = RampMaterial()
    th, td, pd = sample_angles(np.random.default_rng(0), 50)
    lam = np.array([400.0, 550.0, 700.0])
    tgt, valid = material_targets(TrainingMaterial("m", mat, True), th, td, pd, lam)
    wi, wo = io_from_half_diff(th, td, pd)
    assert np.allclose(tgt, mu_law_encode(mat.eval(wi, wo, lam)))
    assert np.array_equal(valid, (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6))


def test_rgb_targets_are_mu_law_of_the_channel_mean():
    """§3.3: g' is the μ-law of the RGB BRDF averaged over channels (not the mean of μ-laws)."""

    class Coloured:
        def eval_rgb(self, wi, wo):
            return np.tile([[0.9, 0.1, 0.02]], (len(wi), 1))

    th, td, pd = sample_angles(np.random.default_rng(1), 10)
    tgt, _ = material_targets(TrainingMaterial("c", Coloured(), False), th, td, pd, None)
    assert np.allclose(tgt, mu_law_encode(np.array(1.02 / 3)))
    assert not np.allclose(tgt, np.mean(mu_law_encode(np.array([0.9, 0.1, 0.02]))))


def test_angles_are_uniform_in_merl_index_space():
    th, td, pd = sample_angles(np.random.default_rng(2), 200_000)
    u = np.sqrt(th / (math.pi / 2))
    hist, _ = np.histogram(u, bins=10, range=(0, 1))
    assert np.all(np.abs(hist / 20_000 - 1) < 0.05)
    assert td.max() <= math.pi / 2 and pd.max() <= math.pi


def test_batch_holds_several_materials_with_per_point_wavelengths():
    spec, _, _ = sets()
    b = make_batch(spec.materials, [im[0] for im in spec.images], np.random.default_rng(0), 64, 4, True,
                   np.linspace(380, 780, 41))
    assert b.images.shape == (3, 3, 32, 32)
    assert b.target.shape == b.wavelength_nm.shape == b.valid.shape == (3, 256)
    assert len(np.unique(b.wavelength_nm)) > 4


def test_learning_rate_decays_in_steps():
    t = TrainConfig(lr=1e-3, lr_decay_every=10, lr_decay=0.5)
    assert lr_at(t, 0) == lr_at(t, 9) == 1e-3
    assert lr_at(t, 10) == 5e-4 and lr_at(t, 25) == 2.5e-4


@pytest.mark.slow
def test_tiny_overfit_reduces_the_loss_tenfold(tmp_path):
    spec, _, _ = sets(1)
    tcfg = TrainConfig(**{**FAST, "steps": 300, "lr": 3e-3, "lr_decay_every": 200, "tv_weight": 0.0,
                          "rgb_weight": 0.0, "val_every": 10 ** 6, "checkpoint_every": 10 ** 6,
                          "spectral_materials_per_step": 1, "angles_per_material": 256})
    res = train(Config(**SMALL), tcfg, spec, MaterialSet([], []), MaterialSet([], []), tmp_path,
                show_progress=False)
    first = np.mean([r["spec"] for r in res.history[:5]])
    last = np.mean([r["spec"] for r in res.history[-20:]])
    assert last < first / 10, (first, last)


def test_training_is_bit_for_bit_deterministic_and_resumable(tmp_path):
    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 6})
    a = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "a", show_progress=False)
    b = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "b", show_progress=False)
    # c: stop after 3 steps (as if interrupted), then resume to 6
    train(Config(**SMALL), dataclasses.replace(tcfg, steps=3), spec, rgb, val, tmp_path / "c",
          show_progress=False)
    c = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "c", resume=True, show_progress=False)
    sa, sb, sc = (load_weights(r.weights).state_dict() for r in (a, b, c))
    for k in sa:
        assert torch.equal(sa[k], sb[k]), k
        assert torch.equal(sa[k], sc[k]), k
    assert [r["loss"] for r in a.history] == [r["loss"] for r in c.history]
    assert (tmp_path / "a" / "history.csv").read_text().count("\n") == 7


def test_weight_average_is_what_the_run_ships_and_it_resumes_bit_for_bit(tmp_path):
    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 6, "ema_decay": 0.5})
    a = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "a", show_progress=False)
    train(Config(**SMALL), dataclasses.replace(tcfg, steps=3), spec, rgb, val, tmp_path / "c",
          show_progress=False)
    c = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "c", resume=True, show_progress=False)
    shipped, resumed = load_weights(a.weights).state_dict(), load_weights(c.weights).state_dict()
    ck = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=True)
    raw, avg = ck["model"], {k[len("module."):]: v for k, v in ck["ema"].items() if k.startswith("module.")}
    w = "encoder.fc.weight"
    assert torch.equal(shipped[w], avg[w]) and not torch.equal(shipped[w], raw[w])
    for k in shipped:
        assert torch.equal(shipped[k], resumed[k]), k
    with pytest.raises(SpecGenError, match="ema_decay"):
        TrainConfig(ema_decay=1.0).validate()


def test_checkpoints_from_before_the_weight_average_still_resume(tmp_path):
    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 3})
    train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path, show_progress=False)
    ck = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    del ck["train_config"]["ema_decay"]                                     # as older runs wrote them
    torch.save(ck, tmp_path / "checkpoint.pt")
    res = train(Config(**SMALL), dataclasses.replace(tcfg, steps=5), spec, rgb, val, tmp_path, resume=True,
                show_progress=False)
    assert res.steps == 5


def test_resume_refuses_a_different_configuration(tmp_path):
    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 3})
    train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path, show_progress=False)
    with pytest.raises(SpecGenError, match="different configuration"):
        train(Config(**SMALL), dataclasses.replace(tcfg, lr=1.0), spec, rgb, val, tmp_path, resume=True,
              show_progress=False)


def test_config_files_load_and_reject_unknown_keys(tmp_path, repo_dir):
    mcfg, tcfg = load_config(repo_dir / "configs" / "default.json")
    assert mcfg == Config.from_dict(json.loads((repo_dir / "configs" / "default.json").read_text())["model"])
    assert tcfg.tv_weight >= 0
    (tmp_path / "c.toml").write_text('[model]\nfeature_dim = 16\naff_map_hw = [4, 4]\n[train]\nsteps = 7\n')
    m, t = load_config(tmp_path / "c.toml")
    assert m.feature_dim == 16 and t.steps == 7
    (tmp_path / "bad.json").write_text('{"train": {"stepz": 3}}')
    with pytest.raises(SpecGenError, match="stepz"):
        load_config(tmp_path / "bad.json")


def test_every_shipped_config_file_passes_the_schema_and_builds_its_model(repo_dir, tmp_path):
    from specgen_addon.train.config_schema import read_config_dict
    from specgen_addon.train.loop import validate_train_config
    from specgen_addon.model import SpecGen, count_parameters

    for path in sorted((repo_dir / "configs").glob("*.json")):
        validate_train_config(path)
        data = read_config_dict(path)   # bases merged, init_weights absolute
        init = data["train"].get("init_weights")
        if init and (repo_dir / "out").resolve() in Path(init).parents:
            # a chained run (lab/README.md): it starts from an earlier run's output, absent from a
            # clean clone, so the shipped weights stand in for the rest of the checks
            data["train"]["init_weights"] = str(repo_dir / "weights" / "specgen_default.pt")
            path = tmp_path / path.name
            path.write_text(json.dumps(data))
        mcfg, _ = load_config(path)
        assert count_parameters(SpecGen(mcfg)) <= 10_000_000, path.name   # the 10 M-parameter model budget


def _component_sets(n: int = 3):
    from specgen_addon.train.lighting_mix import COMPONENTS

    mats = [RampMaterial(a=0.1 + 0.1 * i, b=0.3, alpha=0.1 + 0.1 * i) for i in range(n)]
    tm = [TrainingMaterial(f"m{i}", m, True) for i, m in enumerate(mats)]
    rng = np.random.default_rng(0)
    stacks = []
    for m in mats:
        base = m.image(32)
        stacks.append(np.stack([base * rng.uniform(0.2, 1.0) for _ in COMPONENTS]).astype(np.float16))
    return MaterialSet(tm, stacks), MaterialSet([], []), MaterialSet(tm[:1], stacks[:1])


def test_training_with_lighting_drawn_per_step_is_bit_identical_for_a_seed(tmp_path):
    spec, rgb, val = _component_sets()
    tcfg = TrainConfig(**{**FAST, "steps": 5, "lighting": "mix", "rgb_materials_per_step": 0})
    a = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "a", show_progress=False)
    b = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "b", show_progress=False)
    c = train(Config(**SMALL), dataclasses.replace(tcfg, seed=1), spec, rgb, val, tmp_path / "c",
              show_progress=False)
    sa, sb, sc = (load_weights(r.weights).state_dict() for r in (a, b, c))
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert not all(torch.equal(sa[k], sc[k]) for k in sa)


def test_batches_made_ahead_by_data_workers_train_the_same_weights_bit_for_bit(tmp_path):
    spec, rgb, val = _component_sets()
    tcfg = TrainConfig(**{**FAST, "steps": 7, "lighting": "mix", "max_minutes": 30.0})
    a = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "a", show_progress=False)
    b = train(Config(**SMALL), dataclasses.replace(tcfg, data_workers=2), spec, rgb, val, tmp_path / "b",
              show_progress=False)
    sa, sb = (load_weights(r.weights).state_dict() for r in (a, b))
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert [r["loss"] for r in a.history] == [r["loss"] for r in b.history]


def test_data_workers_stay_a_bounded_number_of_steps_ahead_and_stop_with_the_consumer():
    import multiprocessing as mp

    from specgen_addon.train.prefetch import step_batches

    made = mp.get_context("fork").Value("i", 0)

    def make(step):
        with made.get_lock():
            made.value += 1
        return step * step

    gen = step_batches(make, 3, 1000, workers=2, ahead=4)
    assert [next(gen) for _ in range(3)] == [9, 16, 25]
    gen.close()                                   # the consumer stops early: the pool is torn down
    assert made.value <= 3 + 4
    assert list(step_batches(make, 0, 5, workers=0)) == [0, 1, 4, 9, 16]


def test_lighting_mix_draws_a_new_lighting_every_time():
    from specgen_addon.train.lighting_mix import COMPONENTS, MODE_P, mix_lighting, quantise

    rng = np.random.default_rng(0)
    stack = rng.uniform(0.0, 0.5, size=(len(COMPONENTS), 3, 8, 8)).astype(np.float16)
    images = [mix_lighting(stack, np.random.default_rng([0, s])) for s in range(200)]
    canonical = sum(np.array_equal(im, stack[0].astype(np.float32)) or
                    np.array_equal(im, stack[1].astype(np.float32)) for im in images)
    assert abs(canonical / 200 - MODE_P[0]) < 0.12
    others = [im.tobytes() for im in images if not (np.array_equal(im, stack[0].astype(np.float32)) or
                                                   np.array_equal(im, stack[1].astype(np.float32)))]
    assert len(set(others)) == len(others)  # every non-canonical input is a fresh lighting
    q = quantise(np.full((2, 2, 3), 1.7, np.float32))
    assert np.all(q == 1.0)  # clipped like an 8-bit image


def test_lighting_mix_honours_the_configured_canonical_fraction():
    from specgen_addon.train.lighting_mix import COMPONENTS, MODE_P, mix_lighting

    stack = np.random.default_rng(0).uniform(0.0, 0.5, size=(len(COMPONENTS), 3, 8, 8)).astype(np.float16)

    def canonical_share(**kw) -> float:
        images = [mix_lighting(stack, np.random.default_rng([1, s]), **kw) for s in range(300)]
        return sum(any(np.array_equal(im, stack[j].astype(np.float32)) for j in (0, 1)) for im in images) / 300

    assert canonical_share(canonical_p=1.0) == 1.0
    assert canonical_share(canonical_p=0.0) == 0.0
    assert abs(canonical_share(canonical_p=0.8) - 0.8) < 0.08
    assert abs(canonical_share() - MODE_P[0]) < 0.08


@pytest.mark.parametrize("bad, message", [
    ({"steps": 0}, "steps must be an integer ≥ 1"),
    ({"seed": -1}, "seed must be an integer ≥ 0"),
    ({"corpus_size": 2.5}, "corpus_size must be an integer"),
    ({"families": {"velvet": 1.0}}, "unknown material family 'velvet'"),
    ({"lighting": "sunny"}, "lighting must be"),
    ({"lr": -1.0}, "lr must be"),
    ({"ema_decay": 1.5}, "ema_decay"),
    ({"linear_loss_weight": -1.0}, "linear_loss_weight must be"),
    ({"data_workers": -1}, "data_workers must be an integer ≥ 0"),
    ({"init_weights": "/nonexistent/w.pt"}, "not found"),
    ({"frozen": ["planes"]}, "frozen must list modules"),
    ({"frozen": ["generator"]}, "need init_weights"),
    ({"fresh_encoder": True}, "need init_weights"),
    ({"fresh_encoder": "yes"}, "fresh_encoder must be true or false"),
    ({"recycle_dormant": ["latent"]}, "recycle_dormant = \\['latent'\\] asks for an experiment"),
    ({"family_draw": {"velvet": 1.0}}, "unknown material family 'velvet'"),
    ({"family_draw": {"sheen": -1.0}}, "family weights must be non-negative"),
    ({"families": {"classic": 1.0}, "family_draw": {"sheen": 1.0}}, "family_draw names no family"),
])
def test_bad_training_configs_are_refused_with_one_clear_error(tmp_path, bad, message):
    from specgen_addon.cli.app import main as cli_main

    with pytest.raises(SpecGenError, match=message):
        TrainConfig.from_dict(bad)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"train": bad}))
    assert cli_main(["train", "--config", str(path), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert not (tmp_path / "run").exists()


def test_family_draw_weights_the_steps_by_family_and_leaves_the_corpus_as_it_is(tmp_path):
    from specgen_addon.corpus.generate import generate_mixed_corpus, material_family
    from specgen_addon.train.loop import _draw, family_draw_probabilities

    corpus = [m for m in generate_mixed_corpus(80, seed=0) if m.split == "train"]
    mats = [TrainingMaterial(m.name, m, True) for m in corpus]
    fams = np.array([material_family(m) for m in corpus])
    p = family_draw_probabilities(mats, {"sheen": 3.0, "classic": 1.0})
    assert p[fams == "sheen"].sum() == pytest.approx(0.75) and p[fams == "classic"].sum() == pytest.approx(0.25)
    assert np.ptp(p[fams == "sheen"]) == 0 and not p[(fams != "sheen") & (fams != "classic")].any()
    mset = MaterialSet(mats, [np.zeros((1, 3, 2, 2), np.float32)] * len(mats), draw_p=p)
    rng = np.random.default_rng(0)
    drawn = [material_family(m.brdf) for _ in range(400) for m in _draw(rng, mset, 2, 1.0, 1)[0]]
    assert set(drawn) == {"sheen", "classic"}
    assert abs(drawn.count("sheen") / len(drawn) - 0.75) < 0.06
    with pytest.raises(SpecGenError, match="weights no family of the training set"):
        family_draw_probabilities([m for m, f in zip(mats, fams) if f == "classic"], {"sheen": 1.0})
    spec, rgb, val = sets()                                      # stand-ins: all "classic"
    with pytest.raises(SpecGenError, match="weights no family of the training set"):
        train(Config(**SMALL), TrainConfig(**{**FAST, "family_draw": {"sheen": 1.0}}), spec, rgb, val,
              tmp_path / "run", show_progress=False)
    assert not (tmp_path / "run").exists()


def test_train_command_refuses_bad_overrides_before_any_work(tmp_path, repo_dir):
    from specgen_addon.cli.app import main as cli_main

    cfg = str(repo_dir / "configs" / "default.json")
    assert cli_main(["train", "--config", cfg, "--out", str(tmp_path / "r"), "--steps", "0", "--quiet"]) == 2
    assert cli_main(["train", "--config", cfg, "--out", str(tmp_path / "r"), "--seed", "-3", "--quiet"]) == 2
    assert not (tmp_path / "r").exists()


def test_real_rgl_files_are_held_out_of_default_training(repo_dir):
    # ../shared/data/rgl is real test data: neither the dataclass nor the shipped config trains on it
    _, tcfg = load_config(repo_dir / "configs" / "default.json")
    assert TrainConfig().use_shared_rgl is False and tcfg.use_shared_rgl is False
    assert not any("rgl" in d for d in tcfg.brdf_dirs)
    assert tcfg.corpus_size >= 2000 and tcfg.lighting == "mix" and tcfg.families


def test_component_stacks_resample_like_a_user_image():
    from specgen_addon.model.runtime.inference import resample_square
    from specgen_addon.train.lighting_mix import resample_stack

    rng = np.random.default_rng(0)
    stack = rng.uniform(0, 2, size=(3, 128, 128, 3)).astype(np.float32)
    ours = resample_stack(stack, 64).astype(np.float32)
    ref = np.stack([resample_square(im, 64) for im in stack])
    np.testing.assert_allclose(ours, ref, rtol=1e-3, atol=1e-3)  # float16 storage


def test_a_run_warm_starts_from_one_knot_weights_into_a_knotted_model(tmp_path):
    spec, rgb, val = sets()
    one = Config(**{**SMALL, "spectral_code_knots": 1})
    first = train(one, TrainConfig(**{**FAST, "steps": 3}), spec, rgb, val, tmp_path / "a", show_progress=False)
    knotted = Config(**{**SMALL, "spectral_code_knots": 4})
    tcfg = TrainConfig(**{**FAST, "steps": 2, "init_weights": str(first.weights)})
    grown = train(knotted, tcfg, spec, rgb, val, tmp_path / "b", show_progress=False)
    assert load_weights(grown.weights).cfg.spectral_code_knots == 4
    # the grown network starts where the old one ended: its first loss is the old one's loss there
    again = train(one, dataclasses.replace(tcfg, steps=1), spec, rgb, val, tmp_path / "c", show_progress=False)
    assert grown.history[0]["loss"] == pytest.approx(again.history[0]["loss"], rel=1e-5)


def test_train_command_refuses_weights_of_another_model_before_any_work(tmp_path, repo_dir):
    from specgen_addon.cli.app import main as cli_main

    torch.manual_seed(0)
    from specgen_addon.model import SpecGen, save_weights

    other = save_weights(SpecGen(Config(**SMALL)), tmp_path / "other.pt")
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps({"model": {}, "train": {"init_weights": str(other), "steps": 1}}))
    assert cli_main(["train", "--config", str(path), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert not (tmp_path / "run").exists()


def test_snapshots_hold_what_the_run_would_ship_at_their_step_and_average(tmp_path):
    from specgen_addon.model.average import average_models

    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 6, "ema_decay": 0.5, "snapshot_every": 2, "snapshot_from": 3})
    a = train(Config(**SMALL), tcfg, spec, rgb, val, tmp_path / "a", show_progress=False)
    snaps = sorted((tmp_path / "a" / "snapshots").glob("*.pt"))
    assert [p.name for p in snaps] == ["step000004.pt", "step000006.pt"]
    last, shipped = load_weights(snaps[-1]), load_weights(a.weights)
    assert last.meta["steps"] == 6
    for k, v in shipped.state_dict().items():
        assert torch.equal(v, last.state_dict()[k]), k
    mean = average_models(snaps)
    assert mean.meta["averaged_steps"] == [4, 6]
    # snapshots do not change the run: the same config without them ships the same weights
    b = train(Config(**SMALL), dataclasses.replace(tcfg, snapshot_every=0), spec, rgb, val, tmp_path / "b",
              show_progress=False)
    for k, v in load_weights(b.weights).state_dict().items():
        assert torch.equal(v, shipped.state_dict()[k]), k
    with pytest.raises(SpecGenError, match="snapshot_every"):
        TrainConfig(snapshot_every=-1).validate()


def test_a_run_stopped_before_its_first_step_saves_its_start_and_says_so(tmp_path):
    from specgen_addon.cli.model import train_summary

    spec, rgb, val = sets()
    res = train(Config(**SMALL), TrainConfig(**{**FAST, "steps": 5, "max_minutes": 1e-9}), spec, rgb, val,
                tmp_path / "r", show_progress=False)
    assert res.steps == 0 and res.history == [] and res.stopped_early and Path(res.weights).is_file()
    assert train_summary(res, 10).endswith("0 steps in 0 s (stopped by --max-minutes); "
                                           "no step was trained in this call")


def test_max_minutes_of_a_resumed_run_counts_only_that_calls_time(tmp_path):
    """`--max-minutes` on `--resume` gives the call its own budget: an earlier call's hours (here a
    checkpoint that says it took 10⁶ s) do not stop it before its first step."""
    spec, rgb, val = sets()
    tcfg = TrainConfig(**{**FAST, "steps": 4})
    first = train(Config(**SMALL), dataclasses.replace(tcfg, max_minutes=1e-9), spec, rgb, val, tmp_path / "r",
                  show_progress=False)
    assert first.steps == 0 and first.stopped_early
    ck_path = tmp_path / "r" / "checkpoint.pt"
    ck = torch.load(ck_path, weights_only=True)
    ck["elapsed"] = 1e6
    torch.save(ck, ck_path)
    again = train(Config(**SMALL), dataclasses.replace(tcfg, max_minutes=30.0), spec, rgb, val, tmp_path / "r",
                  resume=True, show_progress=False)
    assert again.steps == 4 and not again.stopped_early and again.wall_seconds > 1e6


def test_a_fresh_encoder_trains_for_the_frozen_decoder_it_was_given(tmp_path):
    spec, rgb, val = sets()
    first = train(Config(**SMALL), TrainConfig(**{**FAST, "steps": 3}), spec, rgb, val, tmp_path / "a",
                  show_progress=False)
    old = load_weights(first.weights)
    leaky = Config(**{**SMALL, "encoder_channels": (8, 16, 16), "encoder_negative_slope": 0.05})
    tcfg = TrainConfig(**{**FAST, "steps": 4, "lr": 1e-2, "init_weights": str(first.weights),
                          "fresh_encoder": True, "frozen": ["generator", "fusion", "mapping"]})
    run = train(leaky, tcfg, spec, rgb, val, tmp_path / "b", show_progress=False)
    new = load_weights(run.weights)
    assert new.cfg.encoder_negative_slope == 0.05 and len(new.cfg.encoder_channels) == 3
    for name in ("generator", "fusion", "mapping"):          # carried over and never moved
        for key, value in getattr(old, name).state_dict().items():
            assert torch.equal(getattr(new, name).state_dict()[key], value), f"{name}.{key} changed"
    again = train(leaky, tcfg, spec, rgb, val, tmp_path / "c", show_progress=False)
    assert torch.equal(load_weights(again.weights).encoder.fc.weight, new.encoder.fc.weight)  # seeded
    fresh_start = train(leaky, dataclasses.replace(tcfg, steps=1, lr=1e-12), spec, rgb, val, tmp_path / "d",
                        show_progress=False)
    assert not torch.allclose(load_weights(fresh_start.weights).encoder.fc.weight, new.encoder.fc.weight)


def test_a_warm_start_refuses_an_encoder_change_unless_the_encoder_is_fresh(tmp_path):
    from specgen_addon.model.grow import can_grow

    wider = Config(**{**SMALL, "encoder_channels": (8, 24)})
    assert not can_grow(Config(**SMALL), wider)
    assert can_grow(Config(**SMALL), wider, fresh_encoder=True)
    assert not can_grow(Config(**SMALL), Config(**{**SMALL, "head_channels": 4}), fresh_encoder=True)
    assert not can_grow(Config(**SMALL), Config(**{**SMALL, "latent_dim": 16}), fresh_encoder=True)


def test_a_frozen_list_that_leaves_nothing_to_train_is_refused(tmp_path):
    from specgen_addon.train.loop import check_frozen

    four = ["encoder", "generator", "fusion", "mapping"]
    with pytest.raises(SpecGenError, match="nothing would train"):
        check_frozen(Config(**SMALL), TrainConfig(frozen=four, init_weights="w.pt"))
    check_frozen(Config(**SMALL), TrainConfig(frozen=four[1:], init_weights="w.pt"))   # the encoder trains
    (tmp_path / "w.pt").write_bytes(b"")
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"model": {}, "train": {"frozen": four, "init_weights": "w.pt"}}))
    with pytest.raises(SpecGenError, match="nothing would train"):
        load_config(cfg)