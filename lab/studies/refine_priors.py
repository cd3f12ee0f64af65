"""Which refinement prior transfers to novel lighting: body spectrum and smoothness, per split.

    python bench/refine_priors.py [--split val|test] [--count 10] [--json out.json]

For the first ``--count`` materials of the 200-material corpus' ``val`` (the default: choose
settings here) or ``test`` split (report there): the canonical photo, the shipped network's table,
and the table refined under each setting; spectral PSNR (20 bands) against the truth on the sphere
under the held-out map ``courtyard`` and the protocol's distant lights, as table (f) of
docs/results_photo_only.md scores SpecGen. Settings: the body prior (``network``: the network's
body spectrum, tinted; ``otsu2018``: a natural reflectance of the body's colour, the default) ×
smoothness (0.01, the old default; 3, the new) × the added angular term. See docs/refinement.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]

from bench.machine import describe_machine  # noqa: E402

SETTINGS = {"network body, smooth 0.01, no added term (old)": ("network", 0.01, False),
            "network body, smooth 3": ("network", 3.0, False),
            "otsu2018 body, smooth 3": ("otsu2018", 3.0, False),
            "otsu2018 body, smooth 3, added term (default)": ("otsu2018", 3.0, True)}
ROLES = ("env_unseen1", "distant")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--split", choices=("val", "test"), default="val")
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--roles", nargs="+", default=list(ROLES),
                    help="paper-tables scene roles (default: %(default)s; env_unseen2 is the 'interior' map)")
    ap.add_argument("--default-only", action="store_true", help="score only the network and the default refinement")
    ap.add_argument("--cache", type=Path, default=None, help="paper-tables cache to reuse ground-truth renders from")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.count < 1:
        ap.error("--count must be at least 1")

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.corpus import generate_corpus
    from specgen_addon.evaluation import protocol, tables
    from specgen_addon.common.cache import cache_root
    from specgen_addon.generate.refine import RefineOptions, refine_brdf

    mats = [m for m in generate_corpus(protocol.CORPUS_SIZE, protocol.CORPUS_SEED)
            if m.split == args.split][:args.count]
    h = tables.Harness(tables.Settings(), args.cache or cache_root() / "refine-priors", log=lambda s: None)
    settings = {k: v for k, v in SETTINGS.items() if not args.default_only or "(default)" in k}
    rows = []
    t0 = time.perf_counter()
    for m in mats:
        photo = input_image.render_input(m).astype(np.float64)
        table = tables.generate_from_photo(input_image.render_input(m), None, h.wl)
        row = {"material": m.name, "kind": m.kind, "source": protocol.spectrum_source(m)}
        candidates = {"network alone": table}
        for label, (prior, smooth, additive) in settings.items():
            opts = RefineOptions(clip_level=None, body_prior=prior, smooth=smooth, additive=additive)
            candidates[label] = refine_brdf(table, photo, options=opts).table
        for label, t in candidates.items():
            scores = []
            for role in args.roles:
                gt = h.ground_truth(m, role)
                scores.append(tables.score(gt.spectral, h._render(t, role).spectral, gt.mask)["psnr_mean"])
            row[label] = scores
        rows.append(row)
        print(f"{m.name} {m.kind:<16} " + "  ".join(f"{k}: " + "/".join(f"{x:.2f}" for x in v) for k, v in row.items()
                                                    if isinstance(v, list)), flush=True)
    labels = ["network alone", *settings]
    summary = {k: float(np.mean([r[k] for r in rows])) for k in labels}
    print(f"\n{describe_machine()}; split {args.split}, {len(rows)} materials, "
          f"{time.perf_counter() - t0:.0f} s; mean spectral PSNR over {', '.join(args.roles)}:")
    for k, v in summary.items():
        print(f"  {k:<36} {v:.2f} dB")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"split": args.split, "rows": rows, "summary": summary,
                                         "machine": describe_machine()}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
