"""Training of SpecGen: data (targets + cached input renders) and the joint RGB/spectral loop.

:func:`build_material_sets` assembles what :func:`specgen_addon.train.loop.train` consumes:

* spectral: the corpus' ``train`` split (plus spectral RGL files from ``brdf_dirs``);
* RGB: the same corpus materials' RGB versions, the real RGL RGB files in ``../shared/data/rgl``
  (when present and ``use_shared_rgl``), and RGB files from ``brdf_dirs`` (MERL/RGL);
* validation: the corpus' ``val`` split (spectral).

Input images are the canonical sphere renders (:mod:`specgen_addon.input_image`) under
``input_variants`` training lightings each, rendered once and cached in ``cache_dir``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from ..model import Config
from .data import InputImageCache, TrainingMaterial, find_brdf_files, load_file_materials
from .loop import MaterialSet, TrainConfig

SHARED_RGL_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgl"


def training_input(brdf, variant: int, image_size: int) -> np.ndarray:
    """Network input ``(3, S, S)``: the canonical sphere render under training lighting ``variant``."""
    from .. import input_image
    from ..infer import resample_square

    rgb = input_image.render_training_input(brdf, variant)
    return resample_square(input_image.prepare_sphere_array(rgb), image_size)


def build_material_sets(mcfg: Config, tcfg: TrainConfig, cache_dir: str | Path,
                        log: Callable[[str], None] = print, progress: bool = False
                        ) -> tuple[MaterialSet, MaterialSet, MaterialSet]:
    """(spectral, rgb, validation) material sets with cached input renders."""
    from ..corpus import generate_corpus

    cache_dir = Path(cache_dir)
    corpus = generate_corpus(tcfg.corpus_size, tcfg.corpus_seed)
    train = [m for m in corpus if m.split == "train"]
    val = [m for m in corpus if m.split == "val"]
    spectral = [TrainingMaterial(m.name, m, True, "train") for m in train]
    rgb = [TrainingMaterial(m.name + "/rgb", m, False, "train") for m in train] if tcfg.rgb_weight > 0 else []
    dirs = [Path(d) for d in tcfg.brdf_dirs]
    if tcfg.use_shared_rgl and SHARED_RGL_DIR.is_dir():
        dirs.append(SHARED_RGL_DIR)
    for mat in load_file_materials(find_brdf_files(dirs), cache_dir, progress=log):
        (spectral if mat.spectral else rgb).append(mat)
    valset = [TrainingMaterial(m.name, m, True, "val") for m in val]

    key = f"{mcfg.image_size}|corpus{tcfg.corpus_size}/{tcfg.corpus_seed}"
    cache = InputImageCache(cache_dir, lambda brdf, k: training_input(brdf, k, mcfg.image_size), key)
    everything = spectral + [m for m in rgb if not m.name.endswith("/rgb")] + valset
    images: dict[str, np.ndarray] = {}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(everything), desc="input renders", unit="mat")
    for mat in everything:
        images[mat.name] = cache.get(mat, tcfg.input_variants)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()

    def imgs(mats: list[TrainingMaterial]) -> list[np.ndarray]:
        # An RGB version sees the same input images as its spectral original.
        return [images[m.name.removesuffix("/rgb")] for m in mats]

    return (MaterialSet(spectral, imgs(spectral)), MaterialSet(rgb, imgs(rgb)),
            MaterialSet(valset, imgs(valset)))


__all__ = ["MaterialSet", "TrainConfig", "build_material_sets", "training_input"]
