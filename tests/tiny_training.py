"""Tiny training runs the training tests share (CPU, a few steps, a few ramp materials).

Import it by name (``from tiny_training import FAST_TRAIN, material_sets``): tests/ is on the test path.
"""

from __future__ import annotations

import dataclasses

from specgen_addon.model import Config, load_weights
from specgen_addon.train.data import TrainingMaterial
from specgen_addon.train.loop import MaterialSet, TrainConfig, train
from specgen_standins import RampMaterial
from tiny_model import TINY_MODEL

#: The tiny network with a wider decoder and finer θ grids, as the training tests train it.
TRAIN_MODEL = {**TINY_MODEL, "decoder_channels": (16, 16), "res_theta_h": 12, "res_theta_d": 12}
#: :class:`TrainConfig` fields of a run of a few steps on a few materials.
FAST_TRAIN = dict(angles_per_material=128, wavelengths_per_angle=4, spectral_materials_per_step=2,
                  rgb_materials_per_step=1, val_every=5, checkpoint_every=3, threads=1, tv_weight=0.1)


def material_sets(n: int = 3) -> tuple[MaterialSet, MaterialSet, MaterialSet]:
    """(spectral, RGB, validation) sets of ``n`` ramp materials with 32 px images."""
    mats = [RampMaterial(a=0.1 + 0.1 * i, b=0.3, alpha=0.1 + 0.1 * i) for i in range(n)]
    tm = [TrainingMaterial(f"m{i}", m, True) for i, m in enumerate(mats)]
    imgs = [m.image(32)[None] for m in mats]
    rgb = [TrainingMaterial(f"m{i}/rgb", m, False) for i, m in enumerate(mats)]
    return MaterialSet(tm, imgs), MaterialSet(rgb, imgs), MaterialSet(tm[:1], imgs[:1])


def twice_and_without(tmp_path, steps: int = 3, **option):
    """Three tiny runs: two with ``option`` set, one with it at its default; (states, results)."""
    spec, rgb, val = material_sets()
    with_option = TrainConfig(**{**FAST_TRAIN, "steps": steps, **option})
    without = dataclasses.replace(with_option, **{k: getattr(TrainConfig(), k) for k in option})
    runs = [train(Config(**TRAIN_MODEL), t, spec, rgb, val, tmp_path / name, show_progress=False)
            for name, t in (("a", with_option), ("b", with_option), ("c", without))]
    return [load_weights(r.weights).state_dict() for r in runs], runs
