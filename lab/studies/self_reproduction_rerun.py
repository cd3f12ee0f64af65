"""Re-run the rows of a self-reproduction study whose refined figure is below a threshold.

    python bench/self_reproduction_rerun.py docs/refinement_study_fifth_session.json --below 42 \\
        --json docs/refinement_study_fifth_session_relaxed.json

The refinement relaxes its smoothness only where self-reproduction is below
``specgen_addon.generate.refine.RELAX_BELOW_DB`` (42 dB), so after that change only those rows can differ:
this re-runs exactly them (self-reproduction only) and writes old and new figures side by side.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


from bench.machine import describe_machine  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", type=Path, help="JSON written by bench/self_reproduction.py --json")
    ap.add_argument("--below", type=float, default=42.0, help="refined self-reproduction (dB) below which to re-run")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if not args.study.is_file():
        ap.error(f"{args.study}: no such study file")
    from specgen_addon.evaluation.protocol import test_materials
    from specgen_addon.evaluation.self_reproduction import study_one
    from specgen_addon.brdf.formats import load_brdf
    from specgen_addon.photo.photo_lighting import parse_lighting

    rows = json.loads(args.study.read_text())["rows"]
    out = []
    for r in [r for r in rows if r["self_psnr_refined"] < args.below]:
        label = r["lighting"]
        name, rot = label.split(" ")[0], 0.0
        if "rot" in label:
            rot = float(label.split("rot ")[1].split("°")[0])
        lighting = parse_lighting("canonical" if label.startswith("canonical") else name, rot)
        rgl = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgl" / f"{r['material']}.bsdf"
        brdf = load_brdf(rgl) if rgl.is_file() else test_materials(names=[r["material"]])[0]
        new = study_one(r["material"], brdf, lighting, novel=False)
        out.append({"material": r["material"], "lighting": label, "before": r["self_psnr_refined"],
                    "before_de": r["self_de_refined"], "after": new["self_psnr_refined"],
                    "after_de": new["self_de_refined"]})
        print(f"{r['material']:<24} {label:<28} {r['self_psnr_refined']:.2f} → {new['self_psnr_refined']:.2f} dB"
              f"  ΔE {r['self_de_refined']:.2f} → {new['self_de_refined']:.2f}", flush=True)
    print(describe_machine())
    if args.json:
        args.json.write_text(json.dumps({"rows": out, "machine": describe_machine()}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
