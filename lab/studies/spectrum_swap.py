"""Is the network's generalisation gap the held-out spectra? Training materials with their spectra swapped.

The network scores its training materials 1.1 dB better than held-out ones, mostly on dielectric
materials (docs/model.md, "The forty-fourth session"). A held-out material differs from a training
one in two ways: its combination of parameters is new, and its measured reflectance spectra come
from source groups the training split never saw (:mod:`specgen_addon.corpus.spectra_sources`).
This bench separates the two on the *same* training materials (every shape parameter kept): each
reflectance is replaced by a measured spectrum drawn at random from one split's source groups
(``--pool train``: spectra the network has seen, in a new combination; ``--pool test``: held-out
spectra), the material is scored as ``evaluate --families`` scores it (canonical input, network
alone, 128², distant lights, 20 bands), and, with ``--baseline`` (the ``evaluate --family-split
train --json`` files of the same materials), paired against its unswapped score. Metals are kept.
The draw for the i-th material uses ``default_rng([seed, i])``, so two pools swap the same
reflectances with the same random stream.

The summary groups the materials by family, by base (dielectric or metal-based) and by where the
original reflectances came from (measured sets, Otsu 2018 draws, or both). ``--pair-with`` adds
the paired difference to another pool's run of the same materials and seed; ``--from-json`` prints
the summary of finished runs without scoring anything again.

Usage: ``.venv/bin/python bench/spectrum_swap.py --pool test [--per-family 30] [--families ...]
[--seed 0] [--baseline A.json B.json] [--json out.json] [--pair-with other.json] [--weights W.pt]``, or
``--from-json test.json --pair-with train.json``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py
from rows import family_groups  # bench/rows.py

REPO = Path(__file__).resolve().parents[2]


def main() -> int:
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.render import metrics
    from specgen_addon.corpus.colour_twin import replace_reflectances
    from specgen_addon.corpus.families import FAMILY_NAMES
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.corpus.material import Reflectance
    from specgen_addon.corpus.spectra_sources import SPLITS, measured_groups
    from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.render import render_spectral, sphere_geometry
    from specgen_addon.evaluation.trained_network import mixed_split_materials

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pool", choices=SPLITS, default=None, help="split whose measured spectra replace the originals")
    ap.add_argument("--per-family", type=int, default=30, help="training materials per family (default 30)")
    ap.add_argument("--families", nargs="+", choices=FAMILY_NAMES, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", type=Path, nargs="+", default=[],
                    help="evaluate --family-split train --json files holding the unswapped scores")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--weights", type=Path, default=None,
                    help="network weights to score (default: the shipped weights/specgen_default.pt)")
    ap.add_argument("--pair-with", type=Path, default=None, metavar="JSON",
                    help="another pool's --json of the same materials and seed: also print this − that, paired")
    ap.add_argument("--from-json", type=Path, default=None, metavar="JSON",
                    help="print the summary of a finished run instead of scoring")
    args = ap.parse_args()
    if (args.pool is None) == (args.from_json is None):
        ap.error("give --pool (score) or --from-json (summarise a finished run)")
    if args.per_family < 1 or args.seed < 0:
        ap.error("--per-family must be ≥ 1 and --seed ≥ 0")
    for path in [*args.baseline, *(p for p in (args.pair_with, args.from_json, args.weights) if p is not None)]:
        if not path.is_file():
            ap.error(f"{path}: file not found")
    if args.json is not None and not args.json.parent.is_dir():
        ap.error(f"{args.json.parent}: folder not found")
    other = None if args.pair_with is None else \
        {r["material"]: r["swapped"] for r in json.loads(args.pair_with.read_text())["materials"]}
    if args.from_json is not None:
        done = json.loads(args.from_json.read_text())
        summarise(done["materials"], done["pool"], other)
        return 0
    baseline = {r["material"]: r["psnr_distant"] for path in args.baseline
                for r in json.loads(path.read_text())["by_family"]["materials"]}

    groups = measured_groups(args.pool)
    wl = np.asarray(WAVELENGTHS_NM, np.float64)
    geo = sphere_geometry(128)
    rows = []
    t0 = time.perf_counter()
    for i, mat in enumerate(mixed_split_materials(args.per_family, args.families, "train")):
        rng = np.random.default_rng([args.seed, i])

        def draw(_: Reflectance) -> Reflectance:
            group = groups[int(rng.integers(len(groups)))]      # a source group, then one member
            s = group[int(rng.integers(len(group)))]
            return Reflectance(f"swap: {s.id}", tuple(round(float(v), 6) for v in s.values))

        swapped = replace_reflectances(mat, draw)
        if swapped is mat:
            continue                                              # no reflectance to swap (a metal)
        table = generate_brdf(input_image.render_input(swapped), weights=args.weights, wavelengths_nm=wl)
        gt = render_spectral(swapped, geo, lights=DISTANT_LIGHTS, wavelengths_nm=wl).spectral
        pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=wl).spectral
        row = {"material": mat.name, "family": material_family(mat), "kind": mat.kind,
               "base": "metal-based" if "metal" in mat.kind or mat.kind.startswith("car_paint") else "dielectric",
               "sources": original_sources(mat),
               "swapped": float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean),
               "original": baseline.get(mat.name)}
        rows.append(row)
        orig = "" if row["original"] is None else f"  unswapped {row['original']:.2f}"
        print(f"{mat.name} {row['family']:<12} {args.pool} spectra {row['swapped']:.2f} dB{orig}", flush=True)

    print(f"\n{describe_machine()}; {len(rows)} training materials with a reflectance, spectra from the "
          f"{args.pool!r} pool ({sum(map(len, groups))} spectra in {len(groups)} groups), {time.perf_counter() - t0:.0f} s")
    summary = summarise(rows, args.pool, other)
    if args.json is not None:
        args.json.write_text(json.dumps({"pool": args.pool, "seed": args.seed, "weights": str(args.weights or "shipped"), "materials": rows,
                                         "families": summary}, indent=1))
    return 0


def original_sources(material: object) -> str:
    """Where ``material``'s reflectances came from: ``measured``, ``drawn`` (Otsu 2018) or ``both``."""
    from specgen_addon.corpus.colour_twin import replace_reflectances

    seen: list[str] = []
    replace_reflectances(material, lambda r: seen.append(r.source) or r)
    drawn = [s.lower().startswith("otsu") for s in seen]
    return "drawn" if all(drawn) else ("measured" if not any(drawn) else "both")


def _mean_se(values: list[float]) -> str:
    v = np.asarray(values, np.float64)
    return f"{v.mean():+.2f} ± {v.std(ddof=1) / np.sqrt(v.size):.2f}" if v.size > 1 else "—"


def summarise(rows: list[dict], pool: str, other: dict[str, float] | None) -> dict:
    """Print (and return) the mean scores and paired differences per family, base and source."""
    groups = list(family_groups(rows, total="all"))
    for key in ("base", "sources"):
        groups += [(f"{key}: {v}", [r for r in rows if r[key] == v]) for v in dict.fromkeys(r[key] for r in rows)]
    print(f"| group | n | unswapped | {pool} spectra | {pool} − unswapped |"
          + (" other pool | this − other |" if other else ""))
    print("| --- | ---: | ---: | ---: | ---: |" + (" ---: | ---: |" if other else ""))
    summary = {}
    for name, sel in groups:
        s = {"n": len(sel), "swapped": float(np.mean([r["swapped"] for r in sel]))}
        line = f"| {name} | {s['n']} | "
        if all(r["original"] is not None for r in sel):
            s["original"] = float(np.mean([r["original"] for r in sel]))
            s["difference"] = _mean_se([r["swapped"] - r["original"] for r in sel])
            line += f"{s['original']:.2f} | {s['swapped']:.2f} | {s['difference']} |"
        else:
            line += f"— | {s['swapped']:.2f} | — |"
        if other:
            s["other"] = float(np.mean([other[r["material"]] for r in sel]))
            s["this_minus_other"] = _mean_se([r["swapped"] - other[r["material"]] for r in sel])
            line += f" {s['other']:.2f} | {s['this_minus_other']} |"
        print(line)
        summary[name] = s
    return summary


if __name__ == "__main__":
    raise SystemExit(main())
