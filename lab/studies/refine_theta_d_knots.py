"""Which θd knots of the refinement's lobe correction follow a thin film's hue shift, on the val split.

    python bench/refine_theta_d_knots.py [--per-family 3] [--families thin_film ...] [--json out.json]

For the first ``--per-family`` *validation* materials of each family of the mixed corpus (the one
``evaluate --families`` draws its test materials from; val spectra and metals are neither train nor
test ones), the canonical photo, the shipped network's table, and the table refined with each θd
knot set of :data:`KNOT_SETS` (everything else the shipped default). Scores:

* spectral PSNR (20 bands) against the truth under the protocol's distant lights and the held-out
  map ``courtyard`` (the ``paper-tables`` roles ``distant`` / ``env_unseen1``);
* the specular colour over θd (θh = 0, θd 0–80°): mean |hue error| (CIELAB h°, D65) and mean
  ΔE2000 with luminance normalised (what ``bench/family_checks.py`` reports on the test split);
* self-reproduction of the photo (RGB PSNR under the input's lighting).

Settings are chosen here, on val; the test split's figures come from ``bench/family_checks.py``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]

from bench.family_checks import THETA_D, _lab, _specular  # noqa: E402
from bench.machine import describe_machine  # noqa: E402

#: Candidate θd knots (MERL grid indices, 1° apart).
KNOT_SETS = {"default (0 30 50 65 77 89)": (0, 30, 50, 65, 77, 89),
             "every 10° (0 10 … 80 89)": (0, 10, 20, 30, 40, 50, 60, 70, 80, 89),
             "every 15° (0 15 … 75 89)": (0, 15, 30, 45, 60, 75, 89)}
ROLES = ("distant", "env_unseen1")


def hue_scores(truth, table) -> tuple[float, float]:
    """(mean |hue error| in degrees, mean Y-normalised ΔE2000) of the specular colour over θd."""
    import colour

    wl = np.asarray(table.wavelengths, dtype=np.float64)  # the truth on the table's bands
    lab_t, lab_p = (_lab(_specular(b, THETA_D, wl), 0.5, wl) for b in (truth, table))
    h = lambda lab: np.degrees(np.arctan2(lab[:, 2], lab[:, 1]))  # noqa: E731
    err = np.abs((h(lab_p) - h(lab_t) + 180.0) % 360.0 - 180.0)
    return float(err.mean()), float(colour.delta_E(lab_t, lab_p, method="CIE 2000").mean())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--per-family", type=int, default=3)
    ap.add_argument("--families", nargs="+", default=None)
    ap.add_argument("--weights", type=Path, default=None)
    ap.add_argument("--knot-sets", nargs="+", type=int, default=None, metavar="I",
                    help="score only these entries of KNOT_SETS (0-based; default: all)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.per_family < 1:
        ap.error("--per-family must be at least 1")

    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.evaluation import tables
    from specgen_addon.common.cache import cache_root
    from specgen_addon.generate.refine import CorrectionBasis, RefineOptions, refine_brdf
    from specgen_addon.evaluation.trained_network import mixed_split_materials

    names = list(KNOT_SETS)
    if args.knot_sets is not None and not all(0 <= i < len(names) for i in args.knot_sets):
        ap.error(f"--knot-sets: indices 0..{len(names) - 1}")
    knot_sets = {names[i]: KNOT_SETS[names[i]] for i in (args.knot_sets or range(len(names)))}
    mats = mixed_split_materials(args.per_family, args.families, "val")
    h = tables.Harness(tables.Settings(), cache_root() / "refine-knots", log=lambda s: None)
    rows = []
    t0 = time.perf_counter()
    for m in mats:
        photo = input_image.render_input(m).astype(np.float64)
        table = tables.generate_from_photo(input_image.render_input(m), args.weights, h.wl)
        row = {"material": m.name, "family": material_family(m), "kind": m.kind}
        candidates = {"network alone": (table, None)}
        for label, knots in knot_sets.items():
            opts = RefineOptions(clip_level=None, basis=CorrectionBasis(theta_d_knots=knots))
            res = refine_brdf(table, photo, options=opts)
            candidates[label] = (res.table, res.after.psnr_db)
        for label, (t, self_psnr) in candidates.items():
            psnr = [tables.score((gt := h.ground_truth(m, r)).spectral, h._render(t, r).spectral, gt.mask)["psnr_mean"]
                    for r in ROLES]
            hue_err, de = hue_scores(m, t)
            row[label] = {"psnr": psnr, "hue_error_deg": hue_err, "dE2000": de, "self_psnr": self_psnr}
        rows.append(row)
        print(f"{m.name} {row['family']:<12} " + " | ".join(
            f"{k[:10]}: {v['psnr'][0]:.2f}/{v['psnr'][1]:.2f} dB, hue {v['hue_error_deg']:.0f}°, ΔE {v['dE2000']:.1f}"
            for k, v in row.items() if isinstance(v, dict)), flush=True)
    labels = ["network alone", *knot_sets]
    print(f"\n{describe_machine()}; val split, {len(rows)} materials, {time.perf_counter() - t0:.0f} s")
    summary: dict = {}
    for fam in sorted({r["family"] for r in rows}) + ["all"]:
        sel = [r for r in rows if fam in ("all", r["family"])]
        summary[fam] = {k: {"psnr_distant": float(np.mean([r[k]["psnr"][0] for r in sel])),
                            "psnr_courtyard": float(np.mean([r[k]["psnr"][1] for r in sel])),
                            "hue_error_deg": float(np.mean([r[k]["hue_error_deg"] for r in sel])),
                            "dE2000": float(np.mean([r[k]["dE2000"] for r in sel]))} for k in labels}
        print(f"{fam} ({len(sel)}):")
        for k, v in summary[fam].items():
            print(f"  {k:<28} distant {v['psnr_distant']:.2f} dB, courtyard {v['psnr_courtyard']:.2f} dB, "
                  f"hue error {v['hue_error_deg']:.1f}°, ΔE2000 {v['dE2000']:.2f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": rows, "summary": summary, "machine": describe_machine()},
                                        indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
