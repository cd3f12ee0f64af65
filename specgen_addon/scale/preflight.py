"""Up-front checks of each CLI command and of ``batch.py``: arguments, files, folders, sizes.

:func:`check_command` runs before a command's own code (``cli.main`` calls it) and
:func:`check_batch` before batch.py's bake, so a bad argument costs milliseconds, not the minutes
of inference, baking or rendering it would otherwise follow. Bounds come from :mod:`.limits`.
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import Callable

from specgen_addon.brdf.formats.export import OUTPUT_SUFFIXES as BRDF_OUTPUT_SUFFIXES
from specgen_addon.common import limits
from specgen_addon.common.errors import ImageInputError, OutputExistsError, SpecGenError, WeightsError
from specgen_addon.corpus.families import check_family_names
from specgen_addon.evaluation.ablation import ARMS_BY_NAME
from specgen_addon.evaluation.ablation_study import load_records
from specgen_addon.evaluation.protocol import test_materials
from specgen_addon.model import DEFAULT_WEIGHTS
from specgen_addon.model.runtime.inference import onnx_paths
from specgen_addon.photo.image_checks import check_image_header
from specgen_addon.photo.sphere_image import output_paths
from specgen_addon.render import environment_maps as lighting
from specgen_addon.render.mesh_checks import check_obj

#: Corpus materials ``render-input`` accepts by name or index without a manifest (standard corpus).
STANDARD_CORPUS_SIZE = 200


def check_image_file(path: str | Path) -> Path:
    """An input image that exists, is readable and whose header size is within the pixel limit."""
    try:
        path = limits.check_input_file(path, "input image")
    except SpecGenError as exc:
        raise ImageInputError(str(exc)) from None
    check_image_header(path)
    return path


def check_brdf_file(path: str | Path) -> Path:
    return limits.check_input_file(path, "BRDF file")


def check_weights_file(path: str | Path | None) -> None:
    if path is not None:
        try:
            limits.check_input_file(path, "weights file")
        except SpecGenError as exc:
            raise WeightsError(str(exc)) from None


# ------------------------------------------------------------------------------------ commands
def _info(a) -> None:
    check_brdf_file(a.file)




def _tabulate(a) -> None:
    check_brdf_file(a.file)
    limits.check_wavelength_range(a.wl_min, a.wl_max, a.bands)
    limits.check_output_file(a.out, a.overwrite, suffixes=BRDF_OUTPUT_SUFFIXES)


def _corpus(a) -> None:
    limits.check_numbers({"n": a.n, "bands": a.bands})
    for name in a.tabulate:
        limits.safe_name(name, "--tabulate material name")
    limits.check_output_dir(a.out)
    for name in a.tabulate:
        limits.refuse_existing(Path(a.out) / f"{name}.npz", a.overwrite)


def _train(a) -> None:
    from specgen_addon.train.loop import validate_train_config

    limits.check_numbers({"steps": a.steps, "max-minutes": a.max_minutes})
    if a.seed is not None and not 0 <= a.seed < 2**32:
        raise SpecGenError(f"--seed must be between 0 and {2**32 - 1}, got {a.seed}")
    cfg = a.config or DEFAULT_WEIGHTS.parents[1] / "configs" / "default.json"
    over = {k: v for k, v in (("steps", a.steps), ("max_minutes", a.max_minutes), ("seed", a.seed),
                              ("device", a.device)) if v is not None}
    validate_train_config(cfg, over)
    from specgen_addon.train.config_schema import read_config_dict
    from specgen_addon.train.distributed import train_device

    if a.show_config:  # prints the resolved config and trains nothing: no device, folder or files
        return
    if a.out is None:
        raise SpecGenError("train needs --out, the folder the run writes (or --show-config to only "
                           "print the configuration)")
    train_device(over.get("device", read_config_dict(cfg).get("train", {}).get("device", "cpu")))  # a GPU?
    for d in a.brdf_dir:
        if not Path(d).is_dir():
            raise SpecGenError(f"{d}: --brdf-dir is not a folder")
    limits.check_output_dir(a.out)
    out = Path(a.out)
    ckpt = out / "checkpoint.pt"
    if a.resume:
        if not ckpt.is_file():
            raise SpecGenError(f"{ckpt}: no checkpoint to resume (run without --resume to start afresh)")
        check_checkpoint(ckpt)
    elif (out / "specgen.pt").exists() or ckpt.exists():
        raise OutputExistsError(f"{out}: holds a training run (pass --resume to continue it, "
                                "or choose another --out)")


def check_checkpoint(path: Path) -> None:
    """A training checkpoint torch can read without unpickling code (corrupt -> one sentence)."""
    import torch

    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt pickles/zips
        raise SpecGenError(f"{path}: corrupt or unreadable checkpoint ({type(exc).__name__}); "
                           "delete it to start afresh") from None
    if not isinstance(ck, dict) or "step" not in ck:
        raise SpecGenError(f"{path}: not a SpecGen training checkpoint")


def _infer(a) -> None:
    check_image_file(a.image)
    check_weights_file(a.weights)
    lo, hi = a.range
    limits.check_wavelength_range(lo, hi, a.bands)
    out = limits.check_output_file(a.output, a.overwrite, suffixes=BRDF_OUTPUT_SUFFIXES)
    if a.rgb:
        limits.check_output_file(out.with_name(out.stem + "_rgb.npz"), a.overwrite)


def _evaluate(a) -> None:
    check_weights_file(a.weights)
    limits.check_number("limit", a.limit)
    if a.json is not None:
        limits.check_output_file(a.json, getattr(a, "overwrite", False))
    if a.input_env is not None:
        if not a.families:
            raise SpecGenError("--input-env needs --families N (it applies to the per-family evaluation)")
        check_env_name(a.input_env)
    shift = a.input_shift
    if not (math.isfinite(shift) and abs(shift) <= 8.0):
        raise SpecGenError(f"--input-shift must be a number of pixels in [-8, 8], got {shift}")
    if shift and not a.families:
        raise SpecGenError("--input-shift needs --families N (it applies to the per-family evaluation)")
    if getattr(a, "family", None):
        if not a.families:
            raise SpecGenError("--family needs --families N "
                               "(it selects the families of the per-family evaluation)")

        check_family_names(a.family)
    if getattr(a, "input_antialias", False):
        if not a.families:
            raise SpecGenError("--input-antialias needs --families N "
                               "(it applies to the per-family evaluation)")
        if a.input_env is not None:
            raise SpecGenError("--input-antialias takes the canonical input; "
                               "it cannot be combined with --input-env")


def _export(a) -> None:
    check_weights_file(a.weights)

    for p in onnx_paths(Path(a.weights) if a.weights is not None else DEFAULT_WEIGHTS):
        limits.refuse_existing(p, a.overwrite)


def _render_input(a) -> None:
    limits.check_numbers({"size": a.size, "variant": a.variant})
    if a.manifest is not None:
        limits.check_input_file(a.manifest, "corpus manifest")
    spec = str(a.material)
    m = re.fullmatch(r"(?:mat)?(\d+)", spec)
    if m and not Path(spec).is_file() and a.manifest is None:
        index = int(m.group(1))
        if index >= STANDARD_CORPUS_SIZE:
            raise SpecGenError(f"{spec}: the standard corpus has materials 0–{STANDARD_CORPUS_SIZE - 1} "
                               "(mat0000–mat0199); pass --manifest for a larger corpus")
    elif Path(spec).exists():
        check_brdf_file(spec)
    limits.check_output_file(a.out, True, suffixes=(".exr", ".png"))

    output_paths(a.out, a.overwrite)


def _paper_tables(a) -> None:
    limits.check_output_file(a.out, overwrite=True)
    if a.img_dir is not None:
        limits.check_output_dir(a.img_dir)
    check_weights_file(a.weights)
    limits.check_numbers({"resolution": a.resolution, "ablation-steps": a.ablation_steps,
                          "budget-minutes": a.budget_minutes})
    if a.materials is not None:
        spec = a.materials.strip()
        if spec.isdigit():
            limits.check_number("materials", int(spec), bounds=(1, 1000))
        elif not [s for s in spec.split(",") if s.strip()]:
            raise SpecGenError("--materials needs a count or comma-separated material names")
        else:
            names = [s.strip() for s in spec.split(",") if s.strip()]
            for s in names:
                limits.safe_name(s, "--materials name")

            test_materials(None, names)  # unknown names refused before any cache is made


def _ablate(a) -> None:
    for f in (a.out, a.json, a.figure):
        if f is not None:
            limits.check_output_file(f, overwrite=True)
    if a.figure is not None and Path(a.figure).suffix.lower() != ".png":
        raise SpecGenError(f"--figure {a.figure}: must end in .png")
    limits.check_numbers({"steps": a.steps})
    limits.check_number("workers", a.workers, bounds=(1, 64))
    limits.check_number("sign-bar", a.sign_bar, bounds=(1.0, 10.0), integer=False)
    limits.check_number("failure-below", a.failure_below, bounds=(0.0, 200.0), integer=False)
    for s in a.seeds:
        limits.check_number("seeds", s, bounds=(0, 2 ** 31 - 1))
    if len(set(a.seeds)) != len(a.seeds):
        raise SpecGenError(f"--seeds must be distinct, got {' '.join(map(str, a.seeds))}")
    unknown = [x for x in a.arms if x not in ARMS_BY_NAME]
    if unknown:
        raise SpecGenError(f"unknown arm {unknown[0]!r}; available: {', '.join(ARMS_BY_NAME)}")
    for f in a.with_records:  # read now, so a bad file is refused before any arm trains
        load_records(limits.check_input_file(f, "ablation records file"), a.steps)


def _average_weights(a) -> None:
    if len(a.sources) < 2:
        raise SpecGenError("average-weights needs at least two weights files or checkpoints")
    for src in a.sources:
        limits.check_input_file(src, "weights file")
    limits.check_output_file(a.output, a.overwrite, suffixes=(".pt",))


CHECKS: dict[str, Callable[[argparse.Namespace], None]] = {
    "info": _info, "tabulate": _tabulate, "corpus": _corpus, "train": _train, "infer": _infer,
    "evaluate": _evaluate, "export-onnx": _export, "render-input": _render_input,
    "paper-tables": _paper_tables, "ablate": _ablate, "average-weights": _average_weights,
}


def check_command(args: argparse.Namespace) -> None:
    """Run the up-front checks of ``args.command`` (no-op for a command without any)."""
    check = CHECKS.get(getattr(args, "command", None) or "")
    if check is not None:
        check(args)


def output_folders(args: argparse.Namespace) -> tuple[list[Path], list[Path]]:
    """(folders a command writes into wholesale, single output files) for :class:`OutputGuard`."""
    cmd = getattr(args, "command", "")
    if cmd in ("corpus", "train"):
        return ([Path(args.out)] if args.out is not None else []), []
    files = []
    for name in ("out", "output", "json", "figure"):
        p = getattr(args, name, None)
        if isinstance(p, (str, Path)):
            files.append(Path(p))
    if cmd == "infer" and getattr(args, "rgb", False):
        out = Path(args.output)
        files.append(out.with_name(out.stem + "_rgb.npz"))
    if cmd == "infer" and getattr(args, "light_probe", None) is not None:   # the unwrapped probe
        out = Path(args.output)
        files.append(out.with_name(out.stem + "_probe.exr"))
    if cmd == "infer" and getattr(args, "circle_preview", None) is not None:
        files.append(Path(args.circle_preview))
    if cmd == "render-input":
        out = Path(args.out)
        files = [out.with_suffix(".exr"), out.with_suffix(".png")]
    return [], files


# ------------------------------------------------------------------------------------ batch.py
def check_env_name(name: str) -> None:
    """An environment map name among Blender's studio lights (no path, no '..')."""
    limits.safe_name(name, "environment name")
    names = lighting.available_envs()
    if name not in names:
        raise SpecGenError(f"no environment map named {name!r}; available: {', '.join(names)}")


def check_batch_settings(args: argparse.Namespace) -> None:
    """batch.py's settings other than its input and output: sizes, wavelengths, weights, mesh and
    environment name (also what ``batch-many --batch-args`` is checked with, before any item runs)."""
    limits.check_numbers({"resolution": args.resolution, "samples": args.samples,
                          "env-samples": args.env_samples})
    limits.check_wavelength_range(args.wl_min, args.wl_max, args.bands)
    check_weights_file(args.weights)
    if args.mesh not in ("sphere", "suzanne"):
        check_obj(args.mesh)
    check_env_name(args.env)


def check_batch(args: argparse.Namespace) -> None:
    """Everything batch.py needs, checked before the network runs: sizes, files, mesh, names,
    output folder and existing outputs (``lookup/`` included)."""
    check_batch_settings(args)
    if args.image:
        check_image_file(args.image)
        source = Path(args.image)
    else:
        limits.check_input_file(args.brdf, "BRDF table")
        source = Path(args.brdf)
    limits.safe_name(source.stem, "input file name")
    out = limits.check_output_dir(args.out)
    mesh_tag = args.mesh if args.mesh in ("sphere", "suzanne") else Path(args.mesh).stem
    target = out / f"{source.stem}_{mesh_tag}_{args.env}.exr"
    lookup = out / "lookup"
    for p in (target, target.with_name(target.stem + "_preview.png"), lookup / f"{source.stem}.npz",
              lookup / f"{source.stem}_lookup.json", lookup / f"{source.stem}_lookup.g00.exr",
              lookup / f"env_{args.env}.exr"):
        limits.check_name_length(p)  # the longest names it will write, before any work
    for p in (target, target.with_name(target.stem + "_preview.png")):
        if p.is_dir():
            raise SpecGenError(f"{p}: is a folder, expected an output file name")
        limits.refuse_existing(p, args.overwrite)
    if lookup.is_symlink() or (lookup.exists() and lookup.resolve().parent != out.resolve()):
        raise SpecGenError(f"{lookup}: is a link; batch.py writes its lookup textures only in a "
                           "real folder inside the output folder (remove the link)")
    if lookup.exists() and not lookup.is_dir():
        raise SpecGenError(f"{lookup}: is a file; batch.py writes its lookup textures in that folder")
    if lookup.is_dir() and any(lookup.iterdir()) and not args.overwrite:
        raise OutputExistsError(f"{lookup}: holds baked lookups of an earlier run "
                                "(pass --overwrite to replace them)")
