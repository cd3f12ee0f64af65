"""Which order of a measured RGL file a MERL-grid table should hold: the table ceiling per order.

A table on the (θh, θd, φd) grid is reciprocal; an RGL file is not quite (8 θi slices, linear
across them). For each real file in ../shared/data/rgl the grid is filled three ways and scored as
:func:`specgen_addon.evaluation.real_files.table_ceiling` scores (64², the protocol's distant lights
and the two held-out maps, against the file rendered with the light as ``wi``):

* ``nearer``: each point in the order whose ``wo`` is nearer the normal (``tabulate_rgl`` before);
* ``mean``: ½ (fr(wi, wo) + fr(wo, wi));
* ``cosine``: (M(wi, wo) + M(wo, wi)) / (cos θi + cos θo), M(a, b) = fr(a, b) cos θb, the
  stored quantity (the candidate: never divides by a grazing cosine alone).

    .venv/bin/python lab/studies/rgl_reciprocity.py --json out/rgl_reciprocity.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from specgen_addon.brdf.formats.rgl import read_rgl  # noqa: E402
from specgen_addon.brdf.rusinkiewicz import io_from_half_diff  # noqa: E402
from specgen_addon.brdf.table import BRDFTable  # noqa: E402
from specgen_addon.evaluation.real_files import score_table  # noqa: E402

RGL = REPO.parent / "shared" / "data" / "rgl"


def tabulate(bsdf, order: str) -> BRDFTable:
    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        if order == "nearer":
            swap = (wi[:, 2] > wo[:, 2])[:, None]
            return bsdf.eval_native(np.where(swap, wo, wi), np.where(swap, wi, wo))
        a, b = bsdf.eval_native(wi, wo), bsdf.eval_native(wo, wi)
        if order == "mean":
            return 0.5 * (a + b)
        ci, co = np.clip(wi[:, 2:3], 0, None), np.clip(wo[:, 2:3], 0, None)
        return (a * co + b * ci) / np.maximum(ci + co, 1e-12)
    return BRDFTable.tabulate(fn, None, bsdf.channels, {})


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path)
    ap.add_argument("--files", nargs="*", default=None, help="file stems (default: all 14)")
    args = ap.parse_args()
    paths = sorted(RGL.glob("*.bsdf"))
    if args.files:
        paths = [p for p in paths if p.stem.replace("_rgb", "") in args.files or p.stem in args.files]
    rows = []
    for p in paths:
        bsdf = read_rgl(p)
        row = {"material": p.stem}
        for order in ("nearer", "mean", "cosine"):
            t0 = time.perf_counter()
            table = tabulate(bsdf, order)
            row[f"seconds_{order}"] = round(time.perf_counter() - t0, 2)
            row |= {f"{order}_{k[5:]}": round(v, 2) for k, v in score_table(p, table).items()}
        print(json.dumps(row), flush=True)
        rows.append(row)
    scenes = [k[len("nearer_"):] for k in rows[0] if k.startswith("nearer_")]
    for order in ("nearer", "mean", "cosine"):
        vals = np.array([[r[f"{order}_{s}"] for s in scenes] for r in rows])
        print(f"{order:7s} mean {vals.mean():.2f}  per scene " +
              " / ".join(f"{v:.2f}" for v in vals.mean(0)) + f"  lowest {vals.min():.2f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
