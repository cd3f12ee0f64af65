"""Network-alone spectral PSNR on the first N materials of any split of the mixed corpus.

`evaluate --families` scores the held-out *test* split only; scoring the *train* split the same
way tells underfitting (train ≈ test, both low) from overfitting (train well above test). Same
protocol as `evaluate`: canonical input, the table path (`generate_brdf`), a 64² sphere under the
protocol's two distant lights, 20 bands.

Usage: ``.venv/bin/python bench/split_psnr.py [--weights W.pt] [--split train] [--n 20]
[--corpus-size 2900]`` (a smaller ``--corpus-size`` is a prefix of the default corpus: the
materials of ``configs/probe_overfit.json`` are ``--corpus-size 80``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py

REPO = Path(__file__).resolve().parents[2]


def main() -> int:
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.corpus.generate import generate_mixed_corpus
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.render import render_spectral, sphere_geometry

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", type=Path, default=None, help="weights (.pt); default: shipped")
    ap.add_argument("--split", choices=("train", "val", "test"), default="train")
    ap.add_argument("--n", type=int, default=20, help="materials (default 20)")
    ap.add_argument("--corpus-size", type=int, default=2900, help="mixed corpus size, seed 0 (default 2900)")
    args = ap.parse_args()
    if args.n < 1 or args.corpus_size < 1:
        ap.error("--n and --corpus-size must be ≥ 1")
    print("machine:", describe_machine())
    geo = sphere_geometry(64)
    mats = [m for m in generate_mixed_corpus(args.corpus_size, 0) if m.split == args.split][:args.n]
    t0 = time.perf_counter()
    scores = []
    for m in mats:
        table = generate_brdf(input_image.render_input(m), weights=args.weights, wavelengths_nm=WAVELENGTHS_NM)
        gt = render_spectral(m, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        scores.append(float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean))
    print(f"weights {args.weights or 'shipped'}: {args.split} split, first {len(scores)} of a "
          f"{args.corpus_size}-material corpus: mean {np.mean(scores):.2f} dB, min {np.min(scores):.2f} dB "
          f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
