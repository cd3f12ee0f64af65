"""Per-family table of one or more ``evaluate --families --json`` results, merged (e.g. the two
halves of a whole-split run made one per core).

Prints, per corpus family and over all synthetic materials: n, mean PSNR (dB) ± its standard error,
and how many materials fall under ``--floor`` (the per-family floor, 32 dB). The real RGL
files are left out, as in :mod:`paired_families`.

    python bench/family_table.py out/bench/whole128_a.json out/bench/whole128_b.json
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from paired_families import synthetic_scores


def family_rows(scores: dict[tuple[str, str], float], floor: float) -> list[tuple[str, int, float, float, int]]:
    """``(family, n, mean dB, standard error of the mean, materials under floor)`` per family
    (sorted), then ``"all"``."""
    groups: dict[str, list[float]] = {}
    for (family, _), v in sorted(scores.items()):
        groups.setdefault(family, []).append(v)
    groups["all"] = list(scores.values())
    rows = []
    for family, vals in groups.items():
        n = len(vals)
        mean = sum(vals) / n
        se = math.sqrt(sum((v - mean) ** 2 for v in vals) / (n - 1) / n) if n > 1 else float("nan")
        rows.append((family, n, mean, se, sum(v < floor for v in vals)))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, nargs="+", help="evaluate --families --json files")
    ap.add_argument("--scene", default="distant", help="scene column (default distant)")
    ap.add_argument("--floor", type=float, default=32.0, help="count materials under this PSNR (default 32 dB)")
    a = ap.parse_args(argv)
    scores: dict[tuple[str, str], float] = {}
    for path in a.results:
        if not path.is_file():
            ap.error(f"{path}: no such file")
        part = synthetic_scores(path, a.scene)
        if set(part) & set(scores):
            ap.error(f"{path}: materials already in an earlier file")
        scores.update(part)
    if not scores:
        ap.error(f"no synthetic rows with a {a.scene} score")
    print(f"{'family':12} {'n':>4} {'mean dB':>8} {'± se':>6} {'< ' + format(a.floor, 'g') + ' dB':>8}")
    for family, n, mean, se, under in family_rows(scores, a.floor):
        print(f"{family:12} {n:4d} {mean:8.2f} {se:6.2f} {under:8d}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
