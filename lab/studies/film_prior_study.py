"""The thin-film fit as the refinement's prior: can the photo choose between it and the network?

The fifteenth session let self-reproduction choose between the refined network and the thin-film
fit, and it always chose the network: the refined table has far more freedom than the film's few
parameters (docs/refinement.md). Here both tables get the same freedom: the thin-film fit's table
is refined exactly as the network's is, so the two refined tables differ only in their prior. Per
photo this scores, against the truth under the protocol's distant lights (spectral PSNR, as
``evaluate --families``):

* ``network``: the network alone; ``shipped``: the network refined (the pipeline's default);
* ``film``: the thin-film fit as ``--model thin-film`` runs it (since the forty-first session with the
  photo's blur modelled where the crop resampled the sphere; the session's own study ran before that);
  ``film refined``: that table refined;
* two choices between ``shipped`` and ``film refined``, made from the photo alone: ``by self``
  (the higher self-reproduction) and ``by held-out`` (the higher :attr:`RefineResult.holdout_db`:
  each refinement fitted to one half of the sphere's pixel blocks predicts the other).

Photos as :mod:`refine_prior_study` makes them (``independent``: other environment samples than the
refinement's operator; ``shifted``: that photo half a pixel off the grid).

    cd bench && python film_prior_study.py --split val --per-family 1 --skip 25 --json ../out/film25.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


ARMS = ("network", "shipped", "film", "film refined", "by self", "by held-out")
PHOTOS = ("independent", "shifted")


def choose(row: dict) -> None:
    """Add the two photo-only choices between the refined network and the refined film to ``row``."""
    film_self = row["self_db"]["film refined"] > row["self_db"]["shipped"]
    held = row["holdout_db"]
    film_held = (held["film refined"] is not None and
                 (held["shipped"] is None or held["film refined"] > held["shipped"]))
    row["truth_db"]["by self"] = row["truth_db"]["film refined" if film_self else "shipped"]
    row["truth_db"]["by held-out"] = row["truth_db"]["film refined" if film_held else "shipped"]
    row["chose_film"] = {"by self": bool(film_self), "by held-out": bool(film_held)}


def summary(rows: list[dict]) -> str:
    """Mean truth per arm, and each arm against the shipped pipeline."""
    lines = []
    for fam in [None] + sorted({r["family"] for r in rows}):
        sel = [r for r in rows if fam is None or r["family"] == fam]
        head = f"{'all' if fam is None else fam} ({len(sel)} photos)"
        lines.append(head + ": " + " | ".join(
            f"{arm} {np.mean([r['truth_db'][arm] for r in sel]):.2f}" for arm in ARMS))
    shipped = np.array([r["truth_db"]["shipped"] for r in rows])
    for arm in ARMS:
        if arm == "shipped":
            continue
        d = np.array([r["truth_db"][arm] for r in rows]) - shipped
        se = d.std(ddof=1) / np.sqrt(d.size) if d.size > 1 else float("nan")
        lines.append(f"{arm} − shipped: {d.mean():+.2f} ± {se:.2f} dB (standard error), worst {d.min():+.2f}, "
                     f"{int(np.sum(d < -1.0))} photos more than 1 dB below")
    for arm in ("by self", "by held-out"):
        films = [r for r in rows if r["chose_film"][arm]]
        lines.append(f"{arm}: chose the film on {len(films)} of {len(rows)} photos "
                     f"({', '.join(sorted({r['family'] for r in films})) or 'none'})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("val", "test"), default="val", help="corpus split (default val)")
    ap.add_argument("--per-family", type=int, default=1, help="materials per family (default 1)")
    ap.add_argument("--skip", type=int, default=0, help="skip the first K materials of each family")
    ap.add_argument("--families", nargs="+", default=None, help="families (default all)")
    ap.add_argument("--photos", nargs="+", default=list(PHOTOS), choices=PHOTOS, help="photos (default both)")
    ap.add_argument("--resolution", type=int, default=128, help="truth render size in pixels (default 128)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    ap.add_argument("--summarise", type=Path, nargs="+", default=None,
                    help="only print the summary of earlier --json files (merged)")
    a = ap.parse_args(argv)
    if a.summarise:
        rows = [r for p in a.summarise for r in json.loads(p.read_text())]
        print(summary(rows))
        return 0
    if not 1 <= a.per_family <= 20 or a.skip < 0:
        ap.error("--per-family must be in 1..20 and --skip ≥ 0")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.corpus.families import FAMILY_NAMES
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.generate.thin_film import fit_thin_film
    from specgen_addon.generate.pipeline import generate, load_photo_crop
    from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf
    from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX
    from specgen_addon.evaluation.trained_network import displaced_input, mixed_split_materials

    unknown = sorted(set(a.families or ()) - set(FAMILY_NAMES))
    if unknown:
        ap.error(f"unknown families {', '.join(unknown)} (choose from {', '.join(FAMILY_NAMES)})")
    materials = mixed_split_materials(a.per_family, a.families, a.split, skip=a.skip)
    if not materials:
        ap.error(f"the {a.split} split has no materials of these families left after --skip {a.skip}")
    rows = []
    for mat in materials:
        fam = material_family(mat)
        score = truth_scorer(mat, a.resolution)
        independent = independent_photo(mat)
        images = {"independent": independent, "shifted": displaced_input(independent, 0.5)}
        for kind in a.photos:
            t0 = time.perf_counter()
            crop, linear = load_photo_crop(images[kind])
            photo = crop.image.astype(np.float64)
            clip = None if linear else CLIP_LEVEL
            opts = RefineOptions(clip_level=clip, score_holdout=True)
            net = generate(images[kind], refine=False, wavelengths_nm=WAVELENGTHS_NM).table
            shipped = refine_brdf(net, photo, None, opts)
            fit = fit_thin_film(photo, None, clip_level=clip,      # as the pipeline's --model thin-film
                                blur_px=(0.0,) if crop.copied else BLUR_CANDIDATES_PX)
            film = fit.table(WAVELENGTHS_NM)
            film_refined = refine_brdf(film, photo, None, opts)
            row = {"material": mat.name, "family": fam, "photo": kind,
                   "film_fit": f"{fit.material.kind}",
                   "truth_db": {"network": score(net), "shipped": score(shipped.table),
                                "film": score(film), "film refined": score(film_refined.table)},
                   "self_db": {"network": shipped.before.psnr_db, "shipped": shipped.after.psnr_db,
                               "film": film_refined.before.psnr_db, "film refined": film_refined.after.psnr_db},
                   "holdout_db": {"shipped": shipped.holdout_db, "film refined": film_refined.holdout_db},
                   "improved": {"shipped": shipped.improved, "film refined": film_refined.improved},
                   "seconds": time.perf_counter() - t0}
            choose(row)
            rows.append(row)
            t, s, h = row["truth_db"], row["self_db"], row["holdout_db"]
            print(f"{mat.name:8} {fam:11} {kind:11} truth: " + " ".join(f"{k} {v:.2f}" for k, v in t.items())
                  + f" | self shipped {s['shipped']:.1f} film-ref {s['film refined']:.1f}"
                  + f" | held-out shipped {h['shipped'] or float('nan'):.1f} film-ref {h['film refined'] or float('nan'):.1f}"
                  + f" ({row['seconds']:.0f} s)", flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    if rows:
        print(summary(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
