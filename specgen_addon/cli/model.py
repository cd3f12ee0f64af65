"""CLI commands of the network: ``train``, ``infer``, ``evaluate``, ``export-onnx``, ``average-weights``."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from specgen_addon.cli.photo_args import (
    add_photo_arguments,
    check_circle_preview,
    photo_inputs,
    print_photo_report,
    print_refinement,
)
from specgen_addon.common.errors import OutputExistsError, SpecGenError
from specgen_addon.common.progress import progress_bar
from specgen_addon.corpus.generate import FAMILY_MIX
from specgen_addon.brdf.formats.export import check_output, write_output
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.common.cache import cache_root
from specgen_addon.generate.pipeline import generate
from specgen_addon.model import DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS
from specgen_addon.spectral.spectra import wavelength_grid



def add_network_arguments(p: argparse.ArgumentParser) -> None:
    """``--weights`` and ``--backend``: which network runs, and on what."""
    p.add_argument("--weights", type=Path, default=None,
                   help="weights (.pt); default: the shipped network for how the sphere was cut "
                        "(copied from a canonical frame, or resampled from a photo)")
    p.add_argument("--backend", choices=("torch", "onnx"), default="torch",
                   help="what runs the network: torch (default) or onnx (onnxruntime, with the graphs "
                        "<stem>.tables.onnx and <stem>.head.onnx beside the weights; export-onnx "
                        "writes them). batch.py and the Blender panel default to onnx where "
                        "onnxruntime is installed")


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("train", help="train SpecGen on the corpus (+ RGB BRDFs) from a config file",
                       description="Joint spectral + RGB training (paper §3.3), on CPU by default (--device). Writes OUT/"
                                   "specgen.pt, checkpoint.pt, history.csv and loss_curve.png. Under "
                                   "torchrun (torchrun --nproc_per_node N -m specgen_addon train ...) "
                                   "each rank trains on a shard of every step's materials with DDP "
                                   "(docs/headless-and-scale.md).")
    p.add_argument("--config", type=Path, default=None,
                   help="JSON/TOML with 'model' and 'train' sections (default: configs/default.json)")
    p.add_argument("--out", type=Path, default=None, help="output directory (required unless --show-config)")
    p.add_argument("--show-config", action="store_true",
                   help="print the configuration the run would use (bases named by 'extends' merged, "
                        "defaults filled in, command-line overrides applied) as JSON and exit")
    p.add_argument("--brdf-dir", type=Path, action="append", default=[],
                   help="extra directory of MERL .binary / RGL .bsdf files (repeatable)")
    p.add_argument("--steps", type=int, default=None, help="override the number of steps")
    p.add_argument("--max-minutes", type=float, default=None,
                   help="stop (and save) after this many minutes, at a step boundary (default: the "
                        "config's max_minutes; where that is unset too, no time limit: the run ends "
                        "after its last step)")
    p.add_argument("--seed", type=int, default=None, help="override the seed")
    p.add_argument("--device", choices=("cpu", "cuda", "auto"), default=None,
                   help="where the network trains (default: the config's, cpu); cuda: one GPU per "
                        "rank, DDP over nccl")
    p.add_argument("--resume", action="store_true", help="continue OUT/checkpoint.pt")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_train)

    p = sub.add_parser("infer", help="generate the spectral BRDF of the material in a sphere image",
                       description="Writes the spectral BRDF (90×90×180×Λ on the MERL grid): a compact "
                                   "material file (.npz, a few MB) by default, the full float32 table with "
                                   "--full-table, or an RGL .bsdf (spectral) or MERL .binary (RGB) export.")
    p.add_argument("image", type=Path, help="image of a material sphere (EXR, PNG, JPEG)")
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="output: .npz (compact material; full table with --full-table), .bsdf or .binary")
    p.add_argument("--full-table", action="store_true",
                   help="write the full float32 table (122 MB at 21 bands) instead of the compact file")
    add_network_arguments(p)
    p.add_argument("--bands", type=int, default=21, help="wavelength bands, 1–128 (default 21)")
    p.add_argument("--every-band", action="store_true",
                   help="the network evaluates every band (default: bands at most 40 nm apart, the "
                        "others interpolated in λ: about 1 s faster, the table within 1 %% rms)")
    p.add_argument("--range", type=float, nargs=2, default=(380.0, 780.0), metavar=("START", "END"),
                   help="wavelength range in nm (default 380 780)")
    p.add_argument("--rgb", action="store_true", help="also write OUTPUT_rgb.npz (RGB projection, D65)")
    add_photo_arguments(p)
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_infer)

    p = sub.add_parser("evaluate", help="PSNR/SSIM of SpecGen on the held-out test materials",
                       description="Renders each test material's sphere under a distant light at 20 "
                                   "wavelengths from the predicted and the true BRDF; prints per-"
                                   "material and mean PSNR/SSIM.")
    add_network_arguments(p)
    p.add_argument("--limit", type=int, default=None, help="only the first N test materials")
    p.add_argument("--json", type=Path, default=None, help="also write the results as JSON")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    p.add_argument("--refine", action=argparse.BooleanOptionalAction, default=True,
                   help="also refine each table to its input photo and report the refined PSNR/SSIM "
                        "and both tables' self-reproduction (RGB PSNR, ΔE2000 under the input "
                        "lighting; default: on)")
    p.add_argument("--families", type=int, default=0, metavar="N",
                   help="also score N test materials per corpus family (mixed corpus of "
                        "configs/default.json) under the distant lights and the held-out maps, and "
                        "the real RGL files in ../shared/data/rgl, each with its self-reproduction "
                        "(the network's table in its photo's own lighting against the photo: RGB "
                        "PSNR, ΔE2000) (default 0: off)")
    p.add_argument("--no-envs", action="store_true", help="with --families: distant lights only")
    p.add_argument("--input-env", default=None, metavar="MAP",
                   help="with --families: photograph each input sphere under this environment map "
                        "(e.g. a held-out one: courtyard, interior) instead of the canonical lighting, "
                        "without telling the network; measures its robustness to the input's lighting")
    p.add_argument("--input-shift", type=float, default=0.0, metavar="PX",
                   help="with --families: move each input sphere by PX pixels right and down inside "
                        "a black border before the sphere is found and cropped (the canonical image is "
                        "128 px); measures how the network takes a sphere a user's crop leaves off "
                        "centre (default 0)")
    p.add_argument("--input-antialias", action="store_true",
                   help="with --families: take each input sphere as a camera or an antialiased render "
                        "does, each pixel the mean over its area (rendered at 4× and box-filtered; "
                        "--input-shift then moves it by quarter pixels)")
    p.add_argument("--family", action="append", default=None, metavar="NAME",
                   help="with --families: score only this family of the default training mix "
                        f"({', '.join(FAMILY_MIX)}; repeat for several); the real RGL files are then skipped")
    p.add_argument("--family-split", choices=("test", "train", "val"), default="test",
                   help="with --families: the corpus split to score (default test, the held-out one; "
                        "train scores the same protocol on materials the network was trained on, and "
                        "leaves out the real RGL files)")
    p.add_argument("--family-resolution", type=int, default=64,
                   help="sphere size (px) of the per-family renders (default 64)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_evaluate)

    p = sub.add_parser("export-onnx", help="export weights to ONNX graphs for onnxruntime",
                       description="Writes <stem>.tables.onnx and <stem>.head.onnx beside the weights.")
    p.add_argument("--weights", type=Path, default=None,
                   help="weights (.pt); default: both shipped networks (copied and resampled inputs)")
    p.add_argument("--overwrite", action="store_true", help="replace existing .onnx graphs")
    p.set_defaults(func=run_export)

    p = sub.add_parser("average-weights", help="average weights files or checkpoints of one run (SWA)",
                       description="Writes the element-wise mean of the given weights files "
                                   "(specgen.pt) or training checkpoints (checkpoint.pt), all of one "
                                   "model configuration: stochastic weight averaging after the fact.")
    p.add_argument("sources", type=Path, nargs="+", help="two or more .pt files")
    p.add_argument("-o", "--output", type=Path, required=True, help="averaged weights file (.pt)")
    p.add_argument("--half", action="store_true", help="store float16 tensors (as the shipped weights)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.set_defaults(func=run_average)
    return p


def film_fit_summary(fit, lighting_label: str) -> str:
    """One line on a thin-film fit: the film found and its self-reproduction."""
    m = fit.material
    note = fit.blur_note()
    blur = f"; {note}" if note else ""
    return (f"thin-film fit: {m.kind}, η_f {m.film_eta:g}, d {m.thickness_nm:g} nm, α {m.alpha:.4g}{blur}; "
            f"self-reproduction under {lighting_label}: {fit.reproduction.text()}")


def run_train(args: argparse.Namespace) -> int:
    import dataclasses

    from specgen_addon.model import DEFAULT_WEIGHTS, count_parameters, load_weights
    from specgen_addon.train import build_material_sets
    from specgen_addon.train import distributed as ddp
    from specgen_addon.train.loop import load_config, plot_history, train

    cfg_path = args.config or DEFAULT_WEIGHTS.parents[1] / "configs" / "default.json"
    mcfg, tcfg = load_config(cfg_path)
    over = {k: v for k, v in (("steps", args.steps), ("max_minutes", args.max_minutes),
                              ("seed", args.seed), ("device", args.device)) if v is not None}
    if args.brdf_dir:
        over["brdf_dirs"] = list(tcfg.brdf_dirs) + [str(d) for d in args.brdf_dir]
    tcfg = dataclasses.replace(tcfg, **over).validate()
    if args.show_config:
        print(json.dumps({"model": mcfg.to_dict(), "train": dataclasses.asdict(tcfg)}, indent=1))
        return 0
    if tcfg.init_weights is not None and not args.resume:  # before the input renders, not after
        from specgen_addon.model.grow import can_grow

        if not can_grow(load_weights(tcfg.init_weights).cfg, mcfg, fresh_encoder=tcfg.fresh_encoder):
            raise SpecGenError(f"{tcfg.init_weights}: weights were made with a different model config")
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise SpecGenError(f"{out}: exists and is not a directory")
    if (out / "specgen.pt").exists() and not args.resume:
        raise OutputExistsError(f"{out}/specgen.pt: exists (pass --resume to continue that run)")
    out.mkdir(parents=True, exist_ok=True)
    dctx = ddp.init_from_env(tcfg.device)  # under torchrun: join the process group; else one process
    say = print if dctx.is_main else ddp.silent  # rank 0 speaks for the job

    cache = cache_root() / "train-data"
    t0 = time.perf_counter()
    with ddp.main_first(dctx):  # rank 0 fills the input-render cache, the others then read it
        spectral, rgb, val = build_material_sets(mcfg, tcfg, cache_dir=cache, log=say,
                                                 progress=not args.quiet and dctx.is_main)
    prep = time.perf_counter() - t0
    say(f"materials: {len(spectral)} spectral, {len(rgb)} RGB, {len(val)} validation "
          f"(inputs ready in {prep:.0f} s)")
    res = train(mcfg, tcfg, spectral, rgb, val, out, resume=args.resume, show_progress=not args.quiet,
                meta={"config_file": str(cfg_path), "data_prep_seconds": round(prep, 1),
                      "world_size": dctx.world_size})
    if not dctx.is_main:
        return 0
    if res.history:  # (a run stopped before its first step has no curve to draw)
        plot_history(res.history, out / "loss_curve.png",
                     title=f"SpecGen training: seed {tcfg.seed}, {res.steps} steps, "
                           f"{res.wall_seconds / 60:.1f} min")
    print(train_summary(res, count_parameters(load_weights(res.weights))))
    return 0


def train_summary(res, parameters: int) -> str:
    """The line ``train`` ends with, for a :class:`~specgen_addon.train.loop.TrainResult`; a run
    stopped by ``--max-minutes`` before its first step has no validation figure to report."""
    note = " (stopped by --max-minutes)" if res.stopped_early else ""
    val = res.history[-1].get("val") if res.history else None
    tail = f"final validation μ-law MSE {val:.4g}" if val is not None else "no step was trained in this call"
    return (f"{res.weights}: {parameters:,} parameters, {res.steps} steps in {res.wall_seconds:.0f} s{note}; "
            f"{tail}")


def run_infer(args: argparse.Namespace) -> int:
    out: Path = args.output
    check_output(out)
    rgb_out = out.with_name(out.stem + "_rgb.npz")
    probe_env = out.with_name(out.stem + "_probe.exr")
    outputs = {"-o": out, **({"the --rgb output": rgb_out} if args.rgb else {})}
    for p in outputs.values():
        if p.exists() and not args.overwrite:
            raise OutputExistsError(f"{p}: already exists (pass --overwrite to replace it)")
    if args.light_probe is not None:
        outputs["the unwrapped chrome ball"] = probe_env
    check_circle_preview(args, args.image, outputs)   # before the photo is read
    wl = wavelength_grid(args.range[0], args.range[1], args.bands)
    source, lighting = photo_inputs(args, args.image, probe_env)
    t0 = time.perf_counter()
    with progress_bar("infer", enabled=not args.quiet) as update:
        generated = generate(source, lighting, refine=args.refine, weights=args.weights,
                             wavelengths_nm=wl, backend=args.backend, progress=update, model=args.model,
                             latent_fit=args.latent_fit, every_band=args.every_band)
    table = generated.table
    dt = time.perf_counter() - t0
    print(f"{out}: spectral BRDF {table.values.shape} ({wl[0]:g}–{wl[-1]:g} nm) in {dt:.1f} s")
    print(write_output(table, out, overwrite=args.overwrite, full_table=args.full_table))
    if "input_sphere" in table.metadata:  # which network: the sphere was copied, or resampled from a photo
        print(f"network: {table.metadata['weights']} (sphere {table.metadata['input_sphere']})")
    print_photo_report(generated, args, source)
    if generated.latent_fit is not None:
        print(generated.latent_fit.summary())
    print_refinement(generated)
    if generated.film_fit is not None:
        print(film_fit_summary(generated.film_fit, lighting.label))
    if args.rgb:
        print(write_output(table.to_rgb(), rgb_out, overwrite=args.overwrite, full_table=args.full_table)
              + ": RGB projection (D65, linear sRGB)")
    return 0


def run_evaluate(args: argparse.Namespace) -> int:
    from specgen_addon.evaluation.trained_network import evaluate_families, evaluate_test_split, format_family_results, format_results

    if args.limit is not None and args.limit < 1:
        raise SpecGenError(f"--limit must be ≥ 1, got {args.limit}")
    if not 16 <= args.family_resolution <= 1024:
        raise SpecGenError(f"--family-resolution must be 16–1024, got {args.family_resolution}")
    if args.families < 0:
        raise SpecGenError(f"--families must be ≥ 0, got {args.families}")
    if args.weights is not None and not args.weights.is_file():
        raise SpecGenError(f"{args.weights}: weights file not found")
    with progress_bar("evaluate", enabled=not args.quiet) as update:
        res = evaluate_test_split(weights=args.weights, limit=args.limit, backend=args.backend,
                                  progress=update, refine=args.refine)
    print(format_results(res))
    if args.families:
        from specgen_addon.train import SHARED_RGL_DIR

        with progress_bar("evaluate families", enabled=not args.quiet) as update:
            res["by_family"] = evaluate_families(weights=args.weights, per_family=args.families,
                                                 envs=not args.no_envs,
                                                 rgl_dir=None if args.family or args.family_split != "test"
                                                 else SHARED_RGL_DIR,
                                                 split=args.family_split,
                                                 families=args.family,
                                                 resolution=args.family_resolution,
                                                 backend=args.backend, progress=update,
                                                 input_env=args.input_env,
                                                 input_shift_px=args.input_shift,
                                                 input_antialias=args.input_antialias)
        print(format_family_results(res["by_family"]))
    if args.json:
        with atomic_write(args.json, overwrite=True) as tmp:
            tmp.write_text(json.dumps(res, indent=1))
    return 0


def run_average(args: argparse.Namespace) -> int:
    from specgen_addon.model import save_weights
    from specgen_addon.model.average import average_models

    model = average_models(args.sources)
    path = save_weights(model, args.output, meta=model.meta, overwrite=args.overwrite, half=args.half)
    print(f"{path}: mean of {len(args.sources)} files, {path.stat().st_size / 1e6:.1f} MB")
    return 0


def run_export(args: argparse.Namespace) -> int:
    from specgen_addon.model.runtime.export_onnx import export_onnx

    sources = [args.weights] if args.weights is not None else [DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS]
    for w in sources:
        if not Path(w).is_file():
            raise SpecGenError(f"{w}: weights file not found")
    for w in sources:
        for p in export_onnx(w, overwrite=args.overwrite):
            print(f"{p}: {p.stat().st_size / 1e6:.1f} MB")
    return 0
