"""Does the training loss see what the metric scores? Per test material, the network's μ-law MSE
(the paper's loss, §3.3) against its rendered spectral PSNR (`evaluate`'s metric).

Training minimises the mean μ-law MSE over materials; `evaluate` reports the mean over materials of
a PSNR of renders normalised by their brightest pixel. If the two ranked materials alike, weighting
each material's loss (for example by its inverse, as a mean of logarithms would) could aim training
at the metric's weak tail. This bench measures the rank correlation first.

The PSNRs come from `evaluate --families N --json F` files (network alone, `by_family` rows); the
μ-law MSE is computed here, with the same weights, on the canonical input, at 4096 angles × 8
bands drawn as training draws them (seed 0).

Usage: ``.venv/bin/python bench/loss_vs_metric.py EVAL.json [EVAL2.json ...] [--per-family 8]
[--weights W.pt] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py

REPO = Path(__file__).resolve().parents[2]


def rank_correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's ρ (ties are not expected in continuous scores)."""
    from scipy.stats import spearmanr

    return float(spearmanr(x, y).statistic)


def main() -> int:
    import torch

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.corpus.generate import generate_mixed_corpus
    from specgen_addon.model.specgen import DEFAULT_WEIGHTS, load_weights
    from specgen_addon.train import network_inputs
    from specgen_addon.train.data import TrainingMaterial, make_batch
    from specgen_addon.train.loop import TARGET_WAVELENGTHS_NM, _tensors
    from specgen_addon.train.losses import masked_mse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scores", type=Path, nargs="+", help="evaluate --families --json files")
    ap.add_argument("--per-family", type=int, default=8, help="first materials per family (default 8)")
    ap.add_argument("--weights", type=Path, default=None, help="weights (.pt); default: shipped framed network")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.per_family < 1:
        ap.error("--per-family must be ≥ 1")
    rows: dict[str, dict] = {}
    for path in args.scores:
        if not path.is_file():
            ap.error(f"{path}: file not found")
        for r in json.loads(path.read_text()).get("by_family", {}).get("materials", []):
            rows[r["material"]] = r
    if not rows:
        ap.error("no per-material rows in the score files (run evaluate --families N --json F)")
    weights = args.weights or DEFAULT_WEIGHTS
    print("machine:", describe_machine())
    model = load_weights(weights)
    torch.set_num_threads(1)
    picked, count = [], {}
    for m in generate_mixed_corpus(2900, 0):
        fam = rows.get(m.name, {}).get("family")
        if m.split == "test" and fam is not None and count.get(fam, 0) < args.per_family:
            picked.append((m, fam))
            count[fam] = count.get(fam, 0) + 1
    t0 = time.perf_counter()
    out = []
    for m, fam in picked:
        image = network_inputs([input_image.render_input(m)], model.cfg.image_size)
        b = make_batch([TrainingMaterial(m.name, m, True, "test")], list(image), np.random.default_rng(0),
                       4096, 8, True, TARGET_WAVELENGTHS_NM)
        t = _tensors(b)
        with torch.no_grad():
            pred = model.query(model.planes(t["images"]), t["theta_h"], t["theta_d"], t["phi_d"],
                               t["wavelength_nm"])
        out.append({"material": m.name, "family": fam, "mu_law_mse": float(masked_mse(pred, t["target"], t["valid"])),
                    "psnr": float(rows[m.name]["psnr_distant"])})
    mse = np.log10([o["mu_law_mse"] for o in out])
    psnr = np.array([o["psnr"] for o in out])
    rho = rank_correlation(mse, psnr)
    print(f"{len(out)} test materials ({args.per_family} per family), {time.perf_counter() - t0:.0f} s")
    print(f"Spearman ρ(log μ-law MSE, rendered PSNR) = {rho:+.2f}  (−1: the loss ranks materials as the metric)")
    print("| material | family | μ-law MSE | rendered PSNR (dB) |\n| --- | --- | ---: | ---: |")
    for o in sorted(out, key=lambda o: o["psnr"])[:10]:
        print(f"| {o['material']} | {o['family']} | {o['mu_law_mse']:.2e} | {o['psnr']:.2f} |")
    if args.json is not None:
        args.json.write_text(json.dumps({"weights": str(weights), "spearman": rho, "materials": out}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
