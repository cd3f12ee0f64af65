"""Pair two ``evaluate --families --json`` results material by material (network against network).

A shipping rule compares a candidate to the shipped network on the same test materials; the
paired difference cancels what the materials share, so its standard error is far smaller than
either mean's. Prints each side's mean PSNR (dB) over the synthetic materials, the paired
difference (candidate − baseline) as mean ± standard error over the materials, its ratio to the
standard error, how many materials the candidate is better on, and per-family means. The real
RGL files (kind "measured", scored in RGB) are left out of the pairing.

    python bench/paired_families.py BASELINE.json CANDIDATE.json [--scene distant]
    python bench/paired_families.py A.json C.json --also-baseline B.json --also-candidate D.json   # halves
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def synthetic_scores(path: Path, scene: str) -> dict[tuple[str, str], float]:
    """``{(family, material): PSNR dB}`` of the synthetic rows of one ``evaluate --json`` file."""
    res = json.loads(path.read_text())
    rows = res.get("by_family", res).get("materials")
    if rows is None:
        raise SystemExit(f"{path}: no per-material rows (was it written by evaluate --families --json?)")
    return {(r["family"], r["material"]): float(r[f"psnr_{scene}"]) for r in rows
            if r.get("kind") != "measured" and f"psnr_{scene}" in r}


def paired(base: dict[tuple[str, str], float], cand: dict[tuple[str, str], float]) -> dict[str, float]:
    """Means, paired difference ± standard error and the better count over the shared materials."""
    keys = sorted(set(base) & set(cand))
    if len(keys) < 2:
        raise SystemExit(f"only {len(keys)} material(s) in common; pairing needs two or more")
    d = [cand[k] - base[k] for k in keys]
    n = len(d)
    mean = sum(d) / n
    se = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1) / n)
    return {"n": n, "baseline": sum(base[k] for k in keys) / n, "candidate": sum(cand[k] for k in keys) / n,
            "diff": mean, "se": se, "ratio": mean / se if se > 0 else math.inf,
            "better": sum(x > 0 for x in d)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("baseline", type=Path)
    ap.add_argument("candidate", type=Path)
    ap.add_argument("--also-baseline", type=Path, action="append", default=[],
                    help="more baseline results (e.g. the other half of a whole-split run); repeatable")
    ap.add_argument("--also-candidate", type=Path, action="append", default=[],
                    help="more candidate results; repeatable")
    ap.add_argument("--scene", default="distant", help="which PSNR column to pair (default: distant)")
    args = ap.parse_args(argv)
    base: dict[tuple[str, str], float] = {}
    cand: dict[tuple[str, str], float] = {}
    for path in [args.baseline, *args.also_baseline]:
        base.update(synthetic_scores(path, args.scene))
    for path in [args.candidate, *args.also_candidate]:
        cand.update(synthetic_scores(path, args.scene))
    s = paired(base, cand)
    print(f"{s['n']} materials, {args.scene} PSNR: baseline {s['baseline']:.2f} dB, candidate {s['candidate']:.2f} dB")
    print(f"paired difference {s['diff']:+.3f} ± {s['se']:.3f} dB ({s['ratio']:+.2f} standard errors), "
          f"better on {s['better']} of {s['n']}")
    for fam in sorted({f for f, _ in set(base) & set(cand)}):
        sub = {k: v for k, v in base.items() if k[0] == fam and k in cand}
        if len(sub) >= 2:
            f = paired(sub, {k: cand[k] for k in sub})
            print(f"  {fam:12s} n={f['n']:3d}  {f['baseline']:.2f} → {f['candidate']:.2f} dB  "
                  f"({f['diff']:+.3f} ± {f['se']:.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
