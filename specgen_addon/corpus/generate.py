"""Deterministic generation of the synthetic spectral BRDF corpus.

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

from specgen_addon.common.errors import SpecGenError
from specgen_addon.corpus.families import CarPaint, Lobes, Sheen, ThinFilm, TintedCoat, check_family_names
from specgen_addon.corpus.material import ClearCoat, Conductor, Dielectric, Material, Reflectance
from specgen_addon.corpus.spectra_sources import (DUPLICATE_RMS, METAL_SPLITS, SPLITS, draw_otsu2018, measured_groups,
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


# --- the mixed-family corpus ------------------------------------------------------------

#: Default share of each family in a mixed corpus (normalised); "classic" is :func:`make_material`.
FAMILY_MIX: dict[str, float] = {"classic": 0.25, "tinted_coat": 0.15, "car_paint": 0.15,
                                "thin_film": 0.15, "sheen": 0.15, "lobes": 0.15}
#: Thin films: index (water/soap 1.33 … TiO₂ 2.4) and thickness (nm), uniform.
FILM_ETA = (1.33, 2.4)
FILM_THICKNESS_NM = (100.0, 900.0)


def check_mix(mix: dict[str, float]) -> dict[str, float]:
    """``mix`` normalised to sum 1; SpecGenError naming an unknown family or a bad weight."""
    if not isinstance(mix, dict) or not mix:
        raise SpecGenError("the family mix must be a non-empty mapping of family → weight")
    check_family_names(mix)
    bad = [k for k, v in mix.items() if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0]
    if bad or sum(mix.values()) <= 0:
        raise SpecGenError(f"family weights must be non-negative numbers with a positive sum, got {mix}")
    total = float(sum(mix.values()))
    return {k: float(v) / total for k, v in mix.items() if v > 0}


def _family_material(family: str, seed: int, index: int, drawn: list[tuple[str, np.ndarray]]):
    """Material ``index`` of family ``family``; split drawn first exactly as :func:`make_material`."""
    rng = np.random.default_rng([seed, index])
    split = SPLITS[int(rng.choice(len(SPLITS), p=[SPLIT_WEIGHTS[s] for s in SPLITS]))]
    name = f"mat{index:04d}"
    n_refl = [0]

    def refl() -> Reflectance:
        n_refl[0] += 1
        r = _draw_reflectance(rng, split, seed, f"{index}.{n_refl[0]}", drawn)  # type: ignore[arg-type]
        if r.source.startswith("Otsu2018/"):
            drawn.append((split, np.asarray(r.values)))
        return r

    def metal() -> Conductor:
        metals = METAL_SPLITS[split]
        return Conductor(metals[rng.integers(len(metals))])

    def dielectric() -> Dielectric:
        return Dielectric(round(float(rng.uniform(*CAUCHY_A)), 5), round(float(rng.uniform(*CAUCHY_B_UM2)), 6))

    def coat(lo_hi=(0.01, 0.12)) -> ClearCoat:
        return ClearCoat(round(_log_uniform(rng, lo_hi), 5), round(float(rng.uniform(*COAT_ETA)), 4))

    if family == "tinted_coat":
        alpha = round(_log_uniform(rng, (0.02, 0.5)), 5)
        base = (Material(name + "/base", split, alpha, metal()) if rng.random() < 0.4 else
                Material(name + "/base", split, alpha, dielectric(), refl()))
        return TintedCoat(name, split, base, coat(), refl(), round(float(rng.uniform(0.3, 1.5)), 4))
    if family == "car_paint":
        return CarPaint(name, split, refl(), metal(), round(_log_uniform(rng, (0.15, 0.5)), 5),
                        round(float(rng.uniform(0.1, 0.6)), 4), coat((0.01, 0.08)))
    if family == "thin_film":
        alpha = round(_log_uniform(rng, (0.01, 0.3)), 5)
        eta = round(float(rng.uniform(*FILM_ETA)), 4)
        d = round(float(rng.uniform(*FILM_THICKNESS_NM)), 2)
        if rng.random() < 0.5:
            return ThinFilm(name, split, alpha, eta, d, metal())
        diffuse = refl() if rng.random() < 0.5 else None
        return ThinFilm(name, split, alpha, eta, d, dielectric(), diffuse)
    if family == "sheen":
        return Sheen(name, split, round(float(rng.uniform(0.2, 1.0)), 4), refl(), refl())
    if family == "lobes":
        u = rng.random()
        if u < 0.4:  # long-tailed GTR
            alpha, gamma, retro, retro_alpha = _log_uniform(rng, (0.02, 0.4)), rng.uniform(1.2, 1.9), 0.0, 0.3
        elif u < 0.7:  # very sharp GGX
            alpha, gamma, retro, retro_alpha = _log_uniform(rng, (0.005, 0.02)), 2.0, 0.0, 0.3
        else:  # retro-reflective
            alpha, gamma = _log_uniform(rng, (0.05, 0.4)), 2.0
            retro, retro_alpha = rng.uniform(0.3, 1.0), rng.uniform(0.2, 0.6)
        return Lobes(name, split, round(float(alpha), 5), round(float(gamma), 4), dielectric(), refl(),
                     round(float(retro), 4), round(float(retro_alpha), 4))
    raise ValueError(f"unknown family {family!r}")  # pragma: no cover - check_mix guards


def family_of(seed: int, index: int, mix: dict[str, float]) -> str:
    """The family of material ``index``: its own stream ``default_rng([seed, index, 1])``."""
    names = sorted(mix)
    p = np.array([mix[k] for k in names], dtype=np.float64)
    return names[int(np.random.default_rng([seed, index, 1]).choice(len(names), p=p / p.sum()))]


def generate_mixed_corpus(n: int, seed: int = 0, mix: dict[str, float] | None = None,
                          progress: Callable[[float], None] | None = None) -> list:
    """``n`` materials across families (``mix``: family → weight, default :data:`FAMILY_MIX`).

    Deterministic in ``(seed, mix)``; a smaller corpus is a prefix of a larger one with the same
    mix. Splits are drawn per material as in :func:`make_material` and every spectrum and metal
    comes from its split's pool, so the test split holds out whole spectra.
    """
    mix = check_mix(FAMILY_MIX if mix is None else mix)
    drawn: list[tuple[str, np.ndarray]] = []
    out = []
    for i in range(n):
        family = family_of(seed, i, mix)
        if family == "classic":
            m = make_material(seed, i, drawn)
            if m.diffuse is not None and m.diffuse.source.startswith("Otsu2018/"):
                drawn.append((m.split, np.asarray(m.diffuse.values)))
        else:
            m = _family_material(family, seed, i, drawn)
        out.append(m)
        if progress is not None:
            progress((i + 1) / n)
    return out


def material_family(material) -> str:
    """``"classic"`` for :class:`Material`, else the family's name."""
    return getattr(type(material), "family", "classic") if not isinstance(material, Material) else "classic"
