"""The material sets of a training run: targets and their cached input renders.

:func:`build_material_sets` assembles what :func:`specgen_addon.train.loop.train` consumes:

* spectral: the corpus' ``train`` split (plus spectral RGL files from ``brdf_dirs``);
* RGB: the same corpus materials' RGB versions, the real RGL RGB files in ``../shared/data/rgl``
  (when present and ``use_shared_rgl``), and RGB files from ``brdf_dirs`` (MERL/RGL);
* validation: the corpus' ``val`` split (spectral).

Input images are the canonical sphere renders (:mod:`specgen_addon.photo.sphere_image`) under
``input_variants`` training lightings each, rendered once and cached in ``cache_dir``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from specgen_addon.model import Config
from specgen_addon.train.data import InputImageCache, TrainingMaterial, find_brdf_files, load_file_materials
from specgen_addon.train.loop import MaterialSet, TrainConfig
from specgen_addon.corpus import generate_corpus
from specgen_addon.corpus.generate import generate_mixed_corpus
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.train.lighting_mix import COMPONENTS, ComponentCache
from specgen_addon.train.network_input import network_inputs
from specgen_addon.train.recolour import AffinePairCache

SHARED_RGL_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgl"


def render_input_variant(brdf, variant: int) -> np.ndarray:
    """Canonical sphere render ``(128, 128, 3)`` of ``brdf`` under training lighting ``variant``."""
    return input_image.render_training_input(brdf, variant)


def build_material_sets(mcfg: Config, tcfg: TrainConfig, cache_dir: str | Path,
                        log: Callable[[str], None] = print, progress: bool = False
                        ) -> tuple[MaterialSet, MaterialSet, MaterialSet]:
    """(spectral, rgb, validation) material sets with cached input renders."""
    cache_dir = Path(cache_dir)
    if tcfg.families is None:
        corpus = generate_corpus(tcfg.corpus_size, tcfg.corpus_seed)
    else:
        corpus = generate_mixed_corpus(tcfg.corpus_size, tcfg.corpus_seed, tcfg.families)
    train = [m for m in corpus if m.split == "train"]
    val = [m for m in corpus if m.split == "val"]
    if tcfg.corpus_train_limit and tcfg.corpus_train_limit < len(train):
        # evenly over the corpus order (every family), and only the validation materials scored
        pick = np.linspace(0, len(train) - 1, tcfg.corpus_train_limit).round().astype(int)
        train, val = [train[i] for i in pick], val[: tcfg.val_materials]
    spectral = [TrainingMaterial(m.name, m, True, "train") for m in train]
    rgb = [TrainingMaterial(m.name + "/rgb", m, False, "train") for m in train] if tcfg.rgb_weight > 0 else []
    dirs = [Path(d) for d in tcfg.brdf_dirs]
    if tcfg.use_shared_rgl and SHARED_RGL_DIR.is_dir():
        dirs.append(SHARED_RGL_DIR)
    for mat in load_file_materials(find_brdf_files(dirs), cache_dir, progress=log):
        (spectral if mat.spectral else rgb).append(mat)
    valset = [TrainingMaterial(m.name, m, True, "val") for m in val]
    if tcfg.lighting == "mix":
        return _mixed_lighting_sets(mcfg, tcfg, cache_dir, spectral, rgb, valset, log, progress)

    cache = InputImageCache(cache_dir, render_input_variant)
    everything = spectral + [m for m in rgb if not m.name.endswith("/rgb")] + valset
    todo = cache.missing(everything, tcfg.input_variants)
    if todo:
        log(f"rendering {len(todo)} input images ({tcfg.input_variants} lightings per material) "
            f"into {cache_dir}")
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc="input renders", unit="img")
    cache.fill(everything, tcfg.input_variants, workers=max(1, tcfg.threads),
               progress=(lambda f: bar.update(round(f * len(todo)) - bar.n)) if bar else None)
    if bar is not None:
        bar.close()
    images = {m.name: network_inputs(cache.load(m, tcfg.input_variants), mcfg.image_size, tcfg.png_augment)
              for m in everything}

    def imgs(mats: list[TrainingMaterial]) -> list[np.ndarray]:
        # An RGB version sees the same input images as its spectral original.
        return [images[m.name.removesuffix("/rgb")] for m in mats]

    return (MaterialSet(spectral, imgs(spectral)), MaterialSet(rgb, imgs(rgb)),
            MaterialSet(valset, imgs(valset)))


def _mixed_lighting_sets(mcfg: Config, tcfg: TrainConfig, cache_dir: Path, spectral, rgb, valset,
                        log: Callable[[str], None], progress: bool):
    """Material sets whose images are lighting-component stacks (:mod:`.lighting_mix`)."""
    cache = ComponentCache(cache_dir)
    valset = valset[: tcfg.val_materials]  # only these are ever used
    everything = spectral + [m for m in rgb if not m.name.endswith("/rgb")] + valset
    todo = cache.missing(everything)
    if todo:
        log(f"rendering {len(todo)} materials under {len(COMPONENTS)} lighting components into {cache_dir}")
    _fill_with_bar(cache.fill, everything, len(todo), tcfg.render_workers, "input renders", progress)
    images = {m.name: cache.load(m, mcfg.image_size) for m in everything}

    def imgs(mats: list[TrainingMaterial]) -> list[np.ndarray]:
        return [images[m.name.removesuffix("/rgb")] for m in mats]

    recolour = None
    if tcfg.recolour_p > 0:
        recolour = _recolour_source(tcfg, cache_dir, spectral, log, progress)  # measured files: no slot
    return (MaterialSet(spectral, imgs(spectral), recolour=recolour), MaterialSet(rgb, imgs(rgb)),
            MaterialSet(valset, imgs(valset)))


def _fill_with_bar(fill: Callable[..., None], mats: list[TrainingMaterial], n_todo: int, workers: int,
                   desc: str, progress: bool) -> None:
    """``fill(mats, workers=…, progress=…)`` with a tqdm bar over the ``n_todo`` missing renders."""
    bar = None
    if progress and n_todo:
        from tqdm import tqdm

        bar = tqdm(total=n_todo, desc=desc, unit="mat", mininterval=5.0)
    fill(mats, workers=workers, progress=(lambda f: bar.update(round(f * n_todo) - bar.n)) if bar else None)
    if bar is not None:
        bar.close()


def _recolour_source(tcfg: TrainConfig, cache_dir: Path, mats: list[TrainingMaterial],
                     log: Callable[[str], None], progress: bool):
    """Per-band canonical renders of the corpus's recolourable training materials (:mod:`.recolour`)."""
    cache = AffinePairCache(cache_dir)
    todo = cache.missing(mats)
    if todo:
        log(f"rendering the two per-band canonical inputs of {len(todo)} materials for recolouring into {cache_dir}")
    _fill_with_bar(cache.fill, mats, len(todo), tcfg.render_workers, "recolour renders", progress)
    return cache.source(mats, tcfg.recolour_p)

