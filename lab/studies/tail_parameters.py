"""Which material parameters the network-alone tail shares, family by family.

Reads ``evaluate --families … --json`` files (per-material distant-light PSNRs of the mixed test
split), regenerates the same corpus (``configs/default.json``'s: 2900 materials, seed 0) to recover each
material's parameters, and prints per family, for each scalar parameter and each reflectance's mean
value over 400–700 nm: Spearman's ρ against the PSNR, and the parameter's median among the materials
under the tail threshold (default 32 dB) and among the rest.

Usage: ``.venv/bin/python bench/tail_parameters.py ../out/s40/whole128_a.json ../out/s40/whole128_b.json
[--tail 32]``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

REPO = Path(__file__).resolve().parents[2]

#: Scalar parameters of the families worth relating to the score (roughness, lobe shape, film).
SCALARS = ("alpha", "roughness", "gamma", "retro_weight", "retro_alpha", "thickness_nm", "film_eta", "coverage",
           "flake_alpha")


def material_features(material) -> dict[str, float]:
    """The material's scalar parameters and each top-level reflectance's mean over 400–700 nm."""
    from specgen_addon.corpus.material import Reflectance

    out = {}
    for field in dataclasses.fields(material):
        value = getattr(material, field.name)
        if field.name in SCALARS and isinstance(value, (int, float)):
            out[field.name] = float(value)
        elif isinstance(value, Reflectance):
            out[f"{field.name} (mean ρ)"] = float(np.mean(value.at(np.arange(400.0, 701.0, 10.0))))
    return out


def main() -> int:
    from specgen_addon.corpus.generate import generate_mixed_corpus
    from specgen_addon.evaluation.trained_network import MIXED_CORPUS_SEED, MIXED_CORPUS_SIZE

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, nargs="+", help="evaluate --families … --json files")
    ap.add_argument("--tail", type=float, default=32.0, help="tail threshold in dB (default 32)")
    args = ap.parse_args()
    for p in args.results:
        if not p.is_file():
            ap.error(f"{p}: file not found")
    rows = {}
    for p in args.results:
        try:
            for r in json.loads(p.read_text())["by_family"]["materials"]:
                if r["family"] != "rgl (real, RGB)":
                    rows[r["material"]] = r
        except (ValueError, KeyError) as exc:
            ap.error(f"{p}: not an evaluate --families JSON ({exc})")
    if not rows:
        ap.error("no corpus materials in the results")
    corpus = {m.name: m for m in generate_mixed_corpus(MIXED_CORPUS_SIZE, MIXED_CORPUS_SEED)}
    for family in sorted({r["family"] for r in rows.values()}):
        names = [n for n, r in rows.items() if r["family"] == family]
        psnr = np.array([rows[n]["psnr_distant"] for n in names])
        feats = [material_features(corpus[n]) for n in names]
        tail = psnr < args.tail
        print(f"\n{family}: {len(names)} materials, mean {psnr.mean():.2f} dB, {int(tail.sum())} under {args.tail:g} dB")
        print(f"  {'parameter':<24} {'ρ(·, PSNR)':>11} {'median, tail':>13} {'median, rest':>13}")
        for key in sorted({k for f in feats for k in f}):
            v = np.array([f.get(key, np.nan) for f in feats])
            ok = ~np.isnan(v)
            if ok.sum() < 8 or np.ptp(v[ok]) == 0:
                continue
            rho = spearmanr(v[ok], psnr[ok]).statistic
            med = [f"{np.median(v[ok & sel]):.3g}" if (ok & sel).any() else "—" for sel in (tail, ~tail)]
            print(f"  {key:<24} {rho:>+11.2f} {med[0]:>13} {med[1]:>13}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
