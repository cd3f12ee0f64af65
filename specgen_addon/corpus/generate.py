"""Deterministic generation of the synthetic spectral BRDF corpus (issue 3, item 1).

Material ``i`` of a corpus with seed ``s`` draws everything from its own stream
``numpy.random.default_rng([s, i])``, so a smaller corpus is a prefix of a larger one and any
material can be regenerated alone. Each material first draws its split (train 70 %, val 10 %,
test 20 %), then its ingredients *from that split's pools only*: measured reflectance groups and
metals of :mod:`.spectra_sources`, or a new Otsu 2018 spectrum that is rejected while it lies
within :data:`~.spectra_sources.DUPLICATE_RMS` of any spectrum of another split.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .material import ClearCoat, Conductor, Dielectric, Material, Reflectance
from .spectra_sources import (DUPLICATE_RMS, METAL_SPLITS, SPLITS, draw_otsu2018, measured_groups,
                              measured_spectra, rms_distance)

#: Probability of each split.
SPLIT_WEIGHTS = {"train": 0.7, "val": 0.1, "test": 0.2}
#: Probability of each base: a plastic (dielectric specular + diffuse) or a metal.
P_METAL = 0.3
#: Probability of a clear coat on top of either base.
P_COAT = 0.15
#: Probability that a plastic's reflectance is measured (else drawn from Otsu 2018's basis).
P_MEASURED = 0.6
#: GGX roughness range (log-uniform) of the base lobe and of a clear coat.
ALPHA_BASE = (0.02, 0.8)
ALPHA_COAT = (0.02, 0.2)
#: Cauchy coefficients of dispersive dielectrics (A; B in µm²), uniform; η(589 nm) ≈ 1.31–1.73.
CAUCHY_A = (1.30, 1.70)
CAUCHY_B_UM2 = (0.002, 0.012)
#: Index of a clear coat (lacquers and varnishes), uniform.
COAT_ETA = (1.45, 1.60)
_MAX_REDRAWS = 50


def _rounded(values: np.ndarray) -> tuple[float, ...]:
    """Six decimals: far below measurement error, and the manifest stays small and exact."""
    return tuple(round(float(x), 6) for x in values)


def _draw_reflectance(rng: np.random.Generator, split: str, seed: int, index: int,
                      drawn: list[tuple[str, np.ndarray]]) -> Reflectance:
    if rng.random() < P_MEASURED:
        groups = measured_groups(split)
        group = groups[rng.integers(len(groups))]
        spectrum = group[rng.integers(len(group))]
        return Reflectance(spectrum.id, _rounded(spectrum.values))
    others = [s.values for s in measured_spectra() if s.split != split]
    others += [v for sp, v in drawn if sp != split]
    others_arr = np.stack(others)
    for _ in range(_MAX_REDRAWS):
        values = draw_otsu2018(rng)
        if rms_distance(values, others_arr).min() >= DUPLICATE_RMS:
            return Reflectance(f"Otsu2018/seed={seed}/{index}", _rounded(values))
    raise RuntimeError(f"material {index}: no Otsu 2018 spectrum unlike the other splits' in "
                       f"{_MAX_REDRAWS} draws")  # pragma: no cover - never observed


def _log_uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(np.exp(rng.uniform(np.log(lo_hi[0]), np.log(lo_hi[1]))))


def make_material(seed: int, index: int, drawn: list[tuple[str, np.ndarray]] | None = None) -> Material:
    """Material ``index`` of the corpus with ``seed`` (``drawn``: earlier materials' Otsu spectra)."""
    drawn = [] if drawn is None else drawn
    rng = np.random.default_rng([seed, index])
    split = SPLITS[int(rng.choice(len(SPLITS), p=[SPLIT_WEIGHTS[s] for s in SPLITS]))]
    alpha = round(_log_uniform(rng, ALPHA_BASE), 5)
    diffuse = None
    if rng.random() < P_METAL:
        metals = METAL_SPLITS[split]
        interface: Dielectric | Conductor = Conductor(metals[rng.integers(len(metals))])
    else:
        interface = Dielectric(round(float(rng.uniform(*CAUCHY_A)), 5),
                               round(float(rng.uniform(*CAUCHY_B_UM2)), 6))
        diffuse = _draw_reflectance(rng, split, seed, index, drawn)
    coat = None
    if rng.random() < P_COAT:
        coat = ClearCoat(round(_log_uniform(rng, ALPHA_COAT), 5), round(float(rng.uniform(*COAT_ETA)), 4))
    return Material(f"mat{index:04d}", split, alpha, interface, diffuse, coat)


def generate_corpus(n: int = 200, seed: int = 0,
                    progress: Callable[[float], None] | None = None) -> list[Material]:
    """``n`` materials, deterministic in ``seed``; ``progress(fraction)`` after each one."""
    drawn: list[tuple[str, np.ndarray]] = []
    out = []
    for i in range(n):
        m = make_material(seed, i, drawn)
        if m.diffuse is not None and m.diffuse.source.startswith("Otsu2018/"):
            drawn.append((m.split, np.asarray(m.diffuse.values)))
        out.append(m)
        if progress is not None:
            progress((i + 1) / n)
    return out
