"""Corpus benchmarks: manifest generation, tabulation, analytic evaluation.

Prints, for the default corpus (200 materials, seed 0):

* seconds to generate the 200 materials and write ``manifest.json`` — in a fresh process
  (imports and loading colour-science's measured spectra included) and warm;
* seconds to tabulate one material on the full MERL grid (90 × 90 × 180 = 1.458 M angles) at the
  default 21 bands, for a plastic, a metal and a clear-coated material (best of ``--repeat``),
  plus the one-off cost of the specular albedo table a process builds at its first plastic;
* analytic ``eval_hd`` throughput on 10⁶ random angle triples, at 21 bands and at 1 band.

With ``--figure PNG`` it also draws the corpus picture of docs/dev/corpus.md: every material as a
small sphere lit by one distant light (linear sRGB through :meth:`Material.eval_rgb`, clipped,
sRGB-encoded), grouped by split, beside the metals' normal-incidence reflectance spectra.

With ``--inputs K`` it instead measures the mixed-family corpus at scale: generating the default
mixed corpus (2900 materials, seed 0) and rendering the training-input lighting components
(:mod:`specgen_addon.train.lighting_mix`) of K train materials per family that share one
environment variant (as the cache's ordering makes them), then extrapolates to every train/val
material the default config renders, on ``--workers`` processes.

Usage: ``.venv/bin/python bench/corpus.py [--repeat N] [--figure docs/img/corpus.png]``
``.venv/bin/python bench/corpus.py --inputs 4 [--workers 2]``
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]

from specgen_addon.corpus import generate_corpus, save_manifest  # noqa: E402
from specgen_addon.corpus.microfacet import _albedo_table  # noqa: E402
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM  # noqa: E402

COLD_SCRIPT = """
import sys, time
t0 = time.perf_counter()
sys.path.insert(0, {repo!r})
from specgen_addon.corpus import generate_corpus, save_manifest
save_manifest({out!r}, generate_corpus(200, seed=0), seed=0, overwrite=True)
print(time.perf_counter() - t0)
"""


def best_of(repeat: int, fn) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def sphere_swatch(material, size: int = 40) -> np.ndarray:
    """RGB image of a sphere seen along −z, lit by a unit D65 distant light (upper left, 45°)."""
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size * 2 - 1
    inside = x * x + y * y < 1
    n = np.stack([x, -y, np.sqrt(np.clip(1 - x * x - y * y, 0, 1))], -1)[inside]
    light = np.array([-0.5, 0.5, 1.0]) / np.sqrt(1.5)
    view = np.array([0.0, 0.0, 1.0])
    # Local frame per pixel: any tangent works for an isotropic BRDF.
    t = np.cross(n, np.array([0.0, 1.0, 0.0]))
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(n, t)
    to_local = lambda v: np.stack([t @ v, b @ v, n @ v], -1)  # noqa: E731
    wi, wo = to_local(light), to_local(view)
    rgb = material.eval_rgb(wi, wo) * np.clip(wi[:, 2], 0, None)[:, None] * np.pi * 0.8
    img = np.ones((size, size, 3))
    from specgen_addon.spectral.spectra import srgb_encode

    img[inside] = srgb_encode(np.clip(rgb, 0, 1))
    return img


def draw_figure(path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from specgen_addon.corpus import METAL_SPLITS, Conductor

    corpus = generate_corpus(200, seed=0)
    fig = plt.figure(figsize=(13, 6.2))
    cols = 20
    for row, split in enumerate(("train", "val", "test")):
        mats = [m for m in corpus if m.split == split]
        rows = -(-len(mats) // cols)
        sheet = np.ones((rows * 42, cols * 42, 3))
        for i, m in enumerate(mats):
            r, c = divmod(i, cols)
            sheet[r * 42 + 1:r * 42 + 41, c * 42 + 1:c * 42 + 41] = sphere_swatch(m)
        ax = fig.add_axes([0.01, [0.36, 0.2, 0.01][row], 0.62, [0.6, 0.13, 0.17][row]])
        ax.imshow(sheet, interpolation="nearest")
        ax.set_title(f"{split}: {len(mats)} materials", fontsize=9, loc="left")
        ax.axis("off")
    ax = fig.add_axes([0.69, 0.1, 0.3, 0.82])
    w = np.linspace(380, 780, 81)
    styles = {"train": "-", "val": "--", "test": ":"}
    for split, metals in METAL_SPLITS.items():
        for metal in metals:
            ax.plot(w, Conductor(metal).fresnel(np.array(1.0), w), styles[split], label=f"{metal} ({split})")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("normal-incidence reflectance F(0°)")
    ax.set_title("metals: measured (η, k) → Fresnel", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    print(f"figure: {path}")


def bench_inputs(per_family: int, workers: int) -> None:
    """Mixed-corpus generation + per-family input-render cost, extrapolated to the default run."""
    from specgen_addon.corpus.generate import generate_mixed_corpus, material_family
    from specgen_addon.train.data import TrainingMaterial
    from specgen_addon.train.lighting_mix import COMPONENTS, ComponentCache, env_variant

    print(f"machine: {describe_machine()}")
    t0 = time.perf_counter()
    corpus = generate_mixed_corpus(2900, 0)
    print(f"generate the mixed corpus (2900 materials): {time.perf_counter() - t0:.1f} s")
    renders = [m for m in corpus if m.split == "train"] + [m for m in corpus if m.split == "val"][:24]
    variant = env_variant(corpus[0].name)
    with tempfile.TemporaryDirectory() as tmp:
        cache = ComponentCache(tmp)
        cache.make(TrainingMaterial(corpus[0].name, corpus[0], True))  # scenes and tables warm
        total = 0.0
        for fam in sorted({material_family(m) for m in corpus}):
            pick = [m for m in corpus if material_family(m) == fam and env_variant(m.name) == variant
                    and m is not corpus[0]][:per_family]
            start = time.perf_counter()
            for m in pick:
                cache.make(TrainingMaterial(m.name, m, True))
            per = (time.perf_counter() - start) / len(pick)
            n = sum(material_family(m) == fam for m in renders)
            total += n * per
            print(f"  {fam:<12} {per:5.2f} s/material ({len(COMPONENTS)} components) × {n} materials")
    print(f"input renders for {len(renders)} materials on {workers} processes: ≈ {total / workers / 60:.1f} min "
          f"(extrapolated; load average above)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--figure", type=Path, help="also draw the corpus contact sheet (PNG)")
    parser.add_argument("--inputs", type=int, default=0, metavar="K",
                        help="measure the mixed corpus and its input renders (K materials per family)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.inputs:
        bench_inputs(args.inputs, args.workers)
        return
    if args.figure:
        draw_figure(args.figure)
    print(f"machine: {describe_machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "manifest.json")
        colds = [float(subprocess.run([sys.executable, "-c", COLD_SCRIPT.format(repo=str(REPO), out=out)],
                                      check=True, capture_output=True, text=True).stdout)
                 for _ in range(args.repeat)]
        print(f"generate 200 materials + write manifest, fresh process: {min(colds):.2f} s "
              f"(best of {args.repeat}; includes imports and colour-science's spectra)")
        generate_corpus(200, seed=0)
        warm = best_of(args.repeat, lambda: save_manifest(out, generate_corpus(200, seed=0), 0, overwrite=True))
        print(f"generate 200 materials + write manifest, warm: {warm:.2f} s")

    _albedo_table.cache_clear()
    start = time.perf_counter()
    _albedo_table()
    print(f"one-off specular albedo table E(μ, α, η): {time.perf_counter() - start:.2f} s")

    corpus = generate_corpus(200, seed=0)
    picks = {"plastic": next(m for m in corpus if m.kind == "plastic"),
             "metal": next(m for m in corpus if m.kind.startswith("metal") and not m.coat),
             "coated": next(m for m in corpus if m.coat is not None)}
    for label, m in picks.items():
        t = best_of(args.repeat, lambda: m.tabulate(DEFAULT_WAVELENGTHS_NM))
        print(f"tabulate {m.name} ({m.kind}), 90×90×180 × {DEFAULT_WAVELENGTHS_NM.size} bands: {t:.2f} s")

    rng = np.random.default_rng(0)
    n = 1_000_000
    th, td, pd = rng.uniform(0, np.pi / 2, n), rng.uniform(0, np.pi / 2, n), rng.uniform(0, np.pi, n)
    for bands in (DEFAULT_WAVELENGTHS_NM, np.array([550.0])):
        for label, m in picks.items():
            m.eval_hd(th[:10], td[:10], pd[:10], bands)
            t = best_of(args.repeat, lambda: m.eval_hd(th, td, pd, bands))
            print(f"eval_hd 1e6 points × {bands.size} band(s), {label}: {t:.2f} s")


if __name__ == "__main__":
    main()
