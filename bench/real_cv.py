"""The network on real materials, cross-validated over the real RGL RGB files.

``baseline``: the given weights (default: the shipped ones, which have never seen a real file, so
every file is held out for them) scored on every real file, network alone and refined, under the
distant lights and the held-out maps, beside each file's own MERL-grid table (the representation's
ceiling; :mod:`specgen_addon.evaluation.real_files`).

``cv``: a k-fold cross-validation. The files are split into ``--folds`` folds (a seeded shuffle);
each fold fine-tunes ``init_weights`` of ``--config`` with the real files of the *other* folds in
joint training (``real_exclude`` = its own files, :mod:`specgen_addon.train.real_rgb`) for the same
``--steps`` (and at most ``--max-minutes``), then scores its held-out files. The control arm is the
same fine-tune without real files (``real_materials_per_step`` 0): it sees no real file, so one run
serves every fold and the gain over it is the real files'. Both arms, and the initial weights, are
also scored on a subset of the synthetic test split (``--synthetic-per-family`` per family, 64²,
distant lights, network alone), paired. Each fold's run and score is kept under ``--out`` and reused,
so an interrupted study continues.

Usage::

    .venv/bin/python bench/real_cv.py baseline --out out/real_baseline
    .venv/bin/python bench/real_cv.py cv --config lab/configs/real_joint_cv.json --folds 7 \\
        --steps 150 --out out/real_cv

Each writes ``report.json`` and ``report.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
from machine import describe_machine  # bench/machine.py, beside this script


def _json(path: Path) -> Any | None:
    from specgen_addon.common.cache import read_json

    return read_json(path)


def _save(path: Path, data: Any) -> None:
    from specgen_addon.common.cache import write_json

    write_json(path, data)


def score_files(files: list[Path], weights: Path | None, out: Path, refine: bool, resolution: int,
                ceiling: bool = False) -> list[dict[str, Any]]:
    """Per-file rows (cached as ``out/<stem>.json``)."""
    from specgen_addon.evaluation.real_files import score_real_file, table_ceiling

    rows = []
    for p in files:
        cell = out / f"{p.stem}.json"
        row = _json(cell)
        if row is None:
            row = score_real_file(p, weights, resolution, refine=refine)
            if ceiling:
                row |= table_ceiling(p, resolution)
            _save(cell, row)
        print(f"  {p.stem}: " + ", ".join(f"{k[5:]} {v:.2f}" for k, v in row.items() if k.startswith("psnr_")),
              flush=True)
        rows.append(row)
    return rows


def synthetic(weights: Path | None, out: Path, per_family: int) -> dict[str, Any]:
    """Network alone on ``per_family`` test materials per family, 64², distant lights (cached)."""
    done = _json(out)
    if done is not None:
        return done
    from specgen_addon.evaluation.trained_network import evaluate_families

    res = evaluate_families(weights=weights, per_family=per_family, envs=False, resolution=64,
                            self_reproduction=False)
    rows = [{"material": r["material"], "family": r["family"], "psnr": r["psnr_distant"]} for r in res["materials"]]
    done = {"per_family": per_family, "rows": rows, "mean": float(np.mean([r["psnr"] for r in rows]))}
    _save(out, done)
    return done


def folds_of(files: list[Path], k: int, seed: int) -> list[list[Path]]:
    """``k`` folds of (nearly) equal size from a seeded shuffle of ``files``."""
    order = np.random.default_rng(seed).permutation(len(files))
    return [[files[i] for i in sorted(order[j::k])] for j in range(k)]


def fine_tune(config: Path, out: Path, steps: int, max_minutes: float | None, exclude: list[str],
              real: bool, wait: bool = False, seed: int | None = None) -> Path:
    """Fine-tune per ``config`` into ``out`` (reused when done): the joint arm trains on the real
    files less ``exclude``, the control arm on none. ``wait``: train nothing, wait for another
    process (``--stage train``) to write the weights."""
    weights = out / "specgen.pt"
    while wait and not weights.is_file():
        time.sleep(20)
    if weights.is_file():
        return weights
    from specgen_addon.common.cache import cache_root
    from specgen_addon.train import build_material_sets
    from specgen_addon.train.loop import load_config, train

    mcfg, tcfg = load_config(config)
    tcfg = dataclasses.replace(tcfg, steps=steps, max_minutes=max_minutes, real_exclude=list(exclude),
                               **({} if real else {"real_materials_per_step": 0}),
                               **({} if seed is None else {"seed": seed}))
    tcfg.validate()
    spectral, rgb, val = build_material_sets(mcfg, tcfg, cache_root() / "train-data")
    res = train(mcfg, tcfg, spectral, rgb, val, out, show_progress=False,
                meta={"config_file": str(config), "real_exclude": list(exclude)})
    print(f"  trained {res.steps} steps in {res.wall_seconds:.0f} s -> {res.weights}", flush=True)
    return res.weights


def table_md(rows: list[dict[str, Any]], cols: list[tuple[str, str]]) -> list[str]:
    """Markdown rows: a file per row, then the mean and the minimum."""
    lines = ["| file | " + " | ".join(h for h, _ in cols) + " |", "| --- |" + " ---: |" * len(cols)]
    for r in rows:
        lines.append(f"| {r['material']} | " + " | ".join(f"{r[k]:.2f}" if k in r else "—" for _, k in cols) + " |")
    for what, fn in (("**mean**", np.mean), ("min", np.min)):
        lines.append(f"| {what} | " + " | ".join(
            f"{fn([r[k] for r in rows]):.2f}" if all(k in r for r in rows) else "—" for _, k in cols) + " |")
    return lines


def run_baseline(args: argparse.Namespace) -> int:
    from specgen_addon.evaluation.real_files import scenes, summarise

    files = sorted(args.rgl.glob("*.bsdf"))
    t0 = time.perf_counter()
    rows = score_files(files, args.weights, args.out / "files", refine=not args.no_refine,
                       resolution=args.resolution, ceiling=True)
    labels = [lab for lab, _ in scenes()]
    report = {"what": "baseline on every real file (none seen in training)", "weights": str(args.weights or "shipped"),
              "resolution": args.resolution, "scenes": labels, "rows": rows, "summary": summarise(rows),
              "machine": describe_machine(), "seconds": round(time.perf_counter() - t0, 1)}
    _save(args.out / "report.json", report)
    cols = [(f"network {lab}", f"psnr_{lab}") for lab in labels]
    cols += [(f"refined {lab}", f"psnr_refined_{lab}") for lab in labels]
    cols += [(f"table ceiling {lab}", f"ceiling_{lab}") for lab in labels]
    md = [(f"Real RGL RGB files, weights {report['weights']}, {args.resolution}² renders, PSNR dB; "
          f"{report['machine']}"), ""] + table_md(rows, cols)
    (args.out / "report.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


def run_cv(args: argparse.Namespace) -> int:
    from specgen_addon.evaluation.real_files import scenes, summarise

    files = sorted(args.rgl.glob("*.bsdf"))
    folds = folds_of(files, args.folds, args.fold_seed)
    labels = [lab for lab, _ in scenes()]
    t0 = time.perf_counter()
    print("control arm (no real files)", flush=True)
    wait = args.stage == "score"
    control_w = fine_tune(args.config, args.out / "control", args.steps, args.max_minutes, [], real=False,
                          wait=wait)
    control_rows, synth = [], {}
    if args.stage != "train":  # the control and the initial weights first, while the folds train
        print("control arm scores", flush=True)
        control_rows = score_files(files, control_w, args.out / "control" / "scores",
                                   not (args.no_refine or args.control_without_refine), args.resolution)
        if args.synthetic_per_family:
            print("synthetic split subset: initial weights, control", flush=True)
            synth = {"initial": synthetic(None, args.out / "synthetic_initial.json", args.synthetic_per_family),
                     "control": synthetic(control_w, args.out / "synthetic_control.json",
                                          args.synthetic_per_family)}
    joint_rows, fold_info = [], []
    for k, held in enumerate(folds):
        names = [p.stem for p in held]
        print(f"fold {k}: held out {', '.join(names)}", flush=True)
        w = fine_tune(args.config, args.out / f"fold{k}", args.steps, args.max_minutes, names, real=True,
                      wait=wait)
        if args.stage == "train":
            continue
        meta = _weights_meta(w)
        fold_info.append({"fold": k, "held_out": names, "weights": str(w), "steps": meta.get("steps"),
                          "wall_seconds": meta.get("wall_seconds")})
        joint_rows += [r | {"fold": k} for r in score_files(held, w, args.out / f"fold{k}" / "scores",
                                                             not args.no_refine, args.resolution)]
        if k == 0 and args.synthetic_per_family:  # while the next fold trains
            print("synthetic split subset: fold 0", flush=True)
            synth["fold0"] = synthetic(w, args.out / "synthetic_fold0.json", args.synthetic_per_family)
    if args.stage == "train":
        return 0
    report = {"what": f"{args.folds}-fold cross-validation over the real RGL RGB files", "config": str(args.config),
              "steps": args.steps, "max_minutes": args.max_minutes, "resolution": args.resolution,
              "scenes": labels, "folds": fold_info, "joint": joint_rows, "control": control_rows,
              "summary": {"joint": summarise(joint_rows), "control": summarise(control_rows)},
              "control_arm": {"weights": str(control_w), **{k: _weights_meta(control_w).get(k)
                                                              for k in ("steps", "wall_seconds")}},
              "synthetic": {k: {"mean": v["mean"], "n": len(v["rows"])} for k, v in synth.items()},
              "machine": describe_machine(), "seconds": round(time.perf_counter() - t0, 1)}
    if synth:
        init = {r["material"]: r["psnr"] for r in synth["initial"]["rows"]}
        for arm in ("control", "fold0"):
            d = np.array([r["psnr"] - init[r["material"]] for r in synth[arm]["rows"]])
            report["synthetic"][arm]["paired_vs_initial"] = {"mean": float(d.mean()),
                                                             "se": float(d.std(ddof=1) / np.sqrt(d.size))}
    _save(args.out / "report.json", report)
    base = _json(args.baseline / "report.json") if args.baseline else None
    base_rows = {r["material"]: r for r in (base or {}).get("rows", [])}
    by_name = {r["material"]: r for r in control_rows}
    merged = [r | {f"control_{k}": by_name[r["material"]][k] for k in by_name[r["material"]] if k.startswith("psnr_")}
              | {f"shipped_{k}": v for k, v in base_rows.get(r["material"], {}).items() if k.startswith("psnr_")}
              for r in sorted(joint_rows, key=lambda r: r["material"])]
    cols = [(f"joint {lab}", f"psnr_{lab}") for lab in labels] + \
           [(f"control {lab}", f"control_psnr_{lab}") for lab in labels]
    if base_rows:
        cols += [(f"shipped {lab}", f"shipped_psnr_{lab}") for lab in labels]
    if not args.no_refine:
        cols += [(f"joint refined {lab}", f"psnr_refined_{lab}") for lab in labels]
        if base_rows:
            cols += [(f"shipped refined {lab}", f"shipped_psnr_refined_{lab}") for lab in labels]
    md = [(f"{report['what']}: {args.steps} steps per fine-tune ({args.config}), {args.resolution}² renders, "
          f"PSNR dB, every file scored by the fold that did not train on it; {report['machine']}"), ""]
    md += table_md(merged, cols)
    for arm, s in report["synthetic"].items():
        pv = s.get("paired_vs_initial")
        md.append(f"\nsynthetic test subset ({s['n']} materials, 64², distant): {arm} {s['mean']:.2f} dB"
                  + (f", paired vs the initial weights {pv['mean']:+.2f} ± {pv['se']:.2f} dB" if pv else ""))
    (args.out / "report.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


def run_seeds(args: argparse.Namespace) -> int:
    """Joint against control on one fold's held-out files, paired per seed (network alone, the
    mean of the scenes over the fold's files): the sign of the real files' share, with its spread
    over training randomness."""
    from specgen_addon.evaluation.real_files import scenes

    files = sorted(args.rgl.glob("*.bsdf"))
    held = folds_of(files, args.folds, args.fold_seed)[args.fold]
    names = [p.stem for p in held]
    labels = [lab for lab, _ in scenes()]
    rows = []
    for seed in args.seeds:
        score = {}
        for arm, real in (("joint", True), ("control", False)):
            out = args.out / f"seed{seed}" / arm
            w = fine_tune(args.config, out, args.steps, None, names if real else [], real=real, seed=seed)
            got = score_files(held, w, out / "scores", False, args.resolution)
            score[arm] = float(np.mean([[r[f"psnr_{lab}"] for lab in labels] for r in got]))
        rows.append({"seed": seed, **score, "difference": score["joint"] - score["control"]})
        print(f"seed {seed}: joint {score['joint']:.2f}, control {score['control']:.2f} dB", flush=True)
    d = np.array([r["difference"] for r in rows])
    report = {"what": f"joint vs control over seeds, fold {args.fold} ({', '.join(names)})",
              "config": str(args.config), "steps": args.steps, "rows": rows,
              "difference": {"mean": float(d.mean()), "sd": float(d.std(ddof=1)) if d.size > 1 else None,
                             "n": int(d.size)}, "machine": describe_machine()}
    _save(args.out / "seeds.json", report)
    print(json.dumps(report["difference"]))
    return 0


def _weights_meta(path: Path) -> dict[str, Any]:
    import torch

    return torch.load(path, map_location="cpu", weights_only=True).get("meta", {})


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="mode", required=True)
    for name in ("baseline", "cv", "seeds"):
        p = sub.add_parser(name)
        p.add_argument("--out", type=Path, required=True)
        p.add_argument("--rgl", type=Path, default=REPO.parent / "shared" / "data" / "rgl")
        p.add_argument("--resolution", type=int, default=64)
        p.add_argument("--no-refine", action="store_true", help="network alone only")
    sub.choices["baseline"].add_argument("--weights", type=Path, default=None)
    cv = sub.choices["cv"]
    cv.add_argument("--config", type=Path, required=True)
    cv.add_argument("--folds", type=int, default=7)
    cv.add_argument("--fold-seed", type=int, default=0)
    cv.add_argument("--steps", type=int, default=150)
    cv.add_argument("--max-minutes", type=float, default=None)
    cv.add_argument("--synthetic-per-family", type=int, default=2)
    cv.add_argument("--baseline", type=Path, default=None,
                    help="a baseline run's --out folder: its figures are set beside the folds'")
    cv.add_argument("--control-without-refine", action="store_true",
                    help="score the control arm network alone only (refinement is the slow part)")
    cv.add_argument("--stage", choices=("all", "train", "score"), default="all",
                    help="train: the fine-tunes only; score: wait for each fine-tune's weights and score "
                         "(two processes, one training while the other scores)")
    sd = sub.choices["seeds"]
    sd.add_argument("--config", type=Path, required=True)
    sd.add_argument("--folds", type=int, default=4)
    sd.add_argument("--fold-seed", type=int, default=0)
    sd.add_argument("--fold", type=int, default=0)
    sd.add_argument("--steps", type=int, default=50)
    sd.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    args = ap.parse_args()
    if not args.rgl.is_dir():
        ap.error(f"{args.rgl}: real RGB folder not found")
    args.out.mkdir(parents=True, exist_ok=True)
    return {"baseline": run_baseline, "cv": run_cv, "seeds": run_seeds}[args.mode](args)


if __name__ == "__main__":
    sys.exit(main())
