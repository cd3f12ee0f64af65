"""``paper-tables``: reproduce the paper's evaluation (tables (a)–(e), plots, real data) in one command."""

from __future__ import annotations

import argparse
from pathlib import Path
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.evaluation.ablation_study import (STUDY_ARMS, STUDY_SEEDS, format_markdown, load_records,
                                                     plot_study, pool_records, run_study, summarise)
from specgen_addon.evaluation.runner import run_paper_tables
from specgen_addon.evaluation.tables import INPUT_PHOTOS


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "paper-tables", help="reproduce the paper's evaluation tables, plots and real-data check",
        description="Evaluate SpecGen against photo-only baselines (an analytic BRDF fitted to the same "
                    "input photo, its colours uplifted to spectra) and oracle per-pixel RGB→spectrum "
                    "uplifting of each scene's own render, on held-out "
                    "corpus materials (sphere and Suzanne; distant lights and seen/unseen environment "
                    "maps), train the equal-budget ablation arms (joint vs spectral-only, AFF vs "
                    "Hadamard), check the real RGL files, and write a markdown report with PNG plots. "
                    "Resumable: finished cells are cached beside the output (in .cache/paper-tables).")
    p.add_argument("--out", required=True, type=Path, help="markdown report to write (e.g. docs/results.md)")
    p.add_argument("--img-dir", type=Path, default=None,
                   help="where the PNG figures go (default: img/ beside --out)")
    p.add_argument("--smoke", action="store_true",
                   help="tiny configuration for CI: 2 materials, 64² renders, ablation arms of a few steps")
    p.add_argument("--materials", default=None,
                   help="number of held-out test materials (first in corpus order), or comma-separated names "
                        "(default: the first 10; 2 with --smoke)")
    p.add_argument("--budget-minutes", type=float, default=None,
                   help="approximate wall-clock budget of each ablation arm; converted once to a fixed "
                        "step count (runs stay deterministic) from a short timing of the training step "
                        "(default: a fixed 500 steps per arm)")
    p.add_argument("--ablation-steps", type=int, default=None,
                   help="exact step count of each ablation arm (overrides --budget-minutes)")
    p.add_argument("--no-ablation", action="store_true", help="skip training the ablation arms")
    p.add_argument("--prepare", action="store_true",
                   help="only compute what needs no shipped weights (ground-truth renders, baselines, "
                        "ablation arms) into the cache for a later full run; writes no report")
    p.add_argument("--report-only", action="store_true",
                   help="compute nothing: rebuild the report and figures from the cache (e.g. after "
                        "editing the discussion file beside the report)")
    p.add_argument("--photo-only", action="store_true",
                   help="run only the photo-only protocol (table (f): analytic BRDF fitted to the input "
                        "photo, uplifted, vs SpecGen) and write a report of that part alone")
    p.add_argument("--weights", type=Path, default=None, help="SpecGen weights (default: the shipped ones)")
    p.add_argument("--resolution", type=int, default=None, help="render size in pixels (default 128)")
    p.add_argument("--input-photo", choices=INPUT_PHOTOS, default=INPUT_PHOTOS[0],
                   help="the sphere photo SpecGen and the photo fits see: 'independent' (default) is "
                        "rendered with other environment samples than the refinement and the fit use, "
                        "as a real photo; 'canonical' shares them, a best case (an inverse crime)")
    p.add_argument("--fresh", action="store_true",
                   help="discard cached renders and scores and start over (trained ablation arms are "
                        "kept: they are deterministic and keyed by their exact configuration)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)
    add_ablate_parser(subparsers)
    return p


def add_ablate_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "ablate", help="seeded ablations: AFF vs Hadamard, joint vs spectral-only (mean ± std over seeds)",
        description="Train the ablation arms from scratch at one equal step budget with several seeds, "
                    "score each on the held-out mixed test split (network alone, distant lights) and "
                    "report each arm's mean ± std and each effect's paired difference with its "
                    "uncertainty. Trained arms are cached (.cache/specgen/ablation): a rerun resumes.")
    p.add_argument("--steps", type=int, default=4000, help="training steps of every arm (default 4000)")
    p.add_argument("--seeds", type=int, nargs="+", default=list(STUDY_SEEDS), help="seeds (default 0 1 2)")
    p.add_argument("--arms", nargs="+", default=list(STUDY_ARMS), help=f"arms (default {' '.join(STUDY_ARMS)})")
    p.add_argument("--workers", type=int, default=2, help="arms trained at once, one core each (default 2)")
    p.add_argument("--out", type=Path, default=None, help="markdown tables to write")
    p.add_argument("--json", type=Path, default=None, help="all records and the summary as JSON")
    p.add_argument("--figure", type=Path, default=None, help="PNG dot plot of every arm's per-seed scores")
    p.add_argument("--sign-bar", type=float, default=2.0, metavar="SE",
                   help="call an effect's sign only when its paired mean is at least this many standard "
                        "errors from zero (default 2; raise it for a study extended after earlier looks, "
                        "e.g. 2.36, Pocock's constant for four looks)")
    p.add_argument("--failure-below", type=float, default=None, metavar="DB",
                   help="also count each arm's failed runs: seeds scoring under this PSNR (dB)")
    p.add_argument("--with-records", type=Path, nargs="+", default=[], metavar="JSON",
                   help="pool this run's arms with an earlier study's records (its --json file, same "
                        "--steps); an (arm, seed) in both must score the same to 0.005 dB, so retraining "
                        "one checks the earlier figures")
    p.set_defaults(func=run_ablate)
    return p


def run_ablate(args: argparse.Namespace) -> int:
    import json

    earlier = [r for path in args.with_records for r in load_records(path, args.steps)]
    study = run_study(args.steps, seeds=args.seeds, arms=args.arms, workers=args.workers,
                      sign_bar=args.sign_bar, failure_below=args.failure_below)
    if earlier:
        records = pool_records(study["records"], earlier)
        study.update(records=records, seeds=sorted({r["seed"] for r in records}),
                     arms=list(dict.fromkeys(r["arm"] for r in records)),
                     pooled_with=[str(p) for p in args.with_records],
                     **summarise(records, sign_bar=args.sign_bar, failure_below=args.failure_below))
    text = format_markdown(study)
    print(text)
    for path, content in ((args.out, text), (args.json, json.dumps(study, indent=1))):
        if path is not None:
            with atomic_write(path, overwrite=True) as tmp:
                tmp.write_text(content, encoding="utf-8")
    if args.figure is not None:
        with atomic_write(args.figure, overwrite=True) as tmp:
            plot_study(study, tmp)
    return 0


def run(args: argparse.Namespace) -> int:
    run_paper_tables(out=args.out, img_dir=args.img_dir, smoke=args.smoke, materials=args.materials,
                     budget_minutes=args.budget_minutes, ablation_steps=args.ablation_steps,
                     ablation=not args.no_ablation, weights=args.weights, resolution=args.resolution,
                     fresh=args.fresh, progress=not args.quiet, prepare=args.prepare,
                     report_only=args.report_only, photo_only=args.photo_only,
                     input_photo=args.input_photo)
    return 0
