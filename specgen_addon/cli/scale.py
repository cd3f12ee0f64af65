"""CLI command ``batch-many``: batch.py's pipeline over a material library on a Dask cluster."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path
from specgen_addon.common.errors import SpecGenError
from specgen_addon.scale.batch_many import BatchManyOptions, DEFAULT_BATCH_SCRIPT, run_batch_many


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "batch-many", help="run batch.py's pipeline on many photos / BRDF files on a Dask cluster",
        description="For every input (photo of a sphere: PNG, JPEG, TIFF, TGA, EXR, HDR or camera "
                    "RAW; or BRDF file .npz/.binary/.bsdf): generate "
                    "the spectral BRDF (refined as batch.py does), bake, render the scene, write the "
                    "spectral EXR and preview into OUT/<name>/. Runs on a local Dask cluster, or on an "
                    "existing one with --scheduler. A rerun skips finished items; a failed item is "
                    "retried, then reported without stopping the others. Writes OUT/report.json; "
                    "exits 1 when an item failed.",
        epilog="Settings for batch.py go in one quoted string, e.g. "
               "--batch-args='--mesh suzanne --env courtyard --samples 32'.")
    p.add_argument("inputs", nargs="*", type=Path, metavar="INPUT",
                   help="photos, BRDF files, or folders holding them (not recursive)")
    p.add_argument("--manifest", type=Path, default=None,
                   help="file listing inputs: one path per line (# comments), or a JSON list")
    p.add_argument("--out", type=Path, required=True, help="output folder (one sub-folder per input)")
    p.add_argument("--batch-args", default="", metavar="'ARGS'",
                   help="batch.py options applied to every item, checked as batch.py checks them "
                        "before any item runs; an option naming a file of its own to write "
                        "(--circle-preview) is refused, as an item writes only into OUT/<name>/")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="use this running Dask scheduler (default: start a LocalCluster here)")
    p.add_argument("--workers", type=int, default=2,
                   help="LocalCluster worker processes, one item each at a time (default 2)")
    p.add_argument("--retries", type=int, default=1,
                   help="extra attempts for an item that crashed or timed out (default 1); "
                        "a bad input is reported at once")
    p.add_argument("--timeout", type=float, default=None,
                   help="seconds allowed for each step of an item (preparing a BRDF file, running "
                        "batch.py); a step that runs longer is stopped (SIGTERM, its clean stop; "
                        "killed 10 s later if still running) and retried like a crash (--retries). "
                        "Default: no time limit")
    p.add_argument("--dashboard-address", default="127.0.0.1:8787",
                   help="LocalCluster dashboard address (default 127.0.0.1:8787, this machine only; "
                        "give HOST:PORT or :PORT to open it to the network; the port is 0-65535, "
                        ":0 picks a free one)")
    p.add_argument("--blender", default=None, metavar="EXE",
                   help="run batch.py inside this Blender (--background) instead of the bpy module")
    p.add_argument("--batch-script", type=Path, default=None, help=argparse.SUPPRESS)
    p.add_argument("--overwrite", action="store_true",
                   help="redo items whose folder holds results of another input or other settings")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    try:
        batch_args = shlex.split(args.batch_args)
    except ValueError as exc:
        raise SpecGenError(f"--batch-args: {exc}") from None
    opts = BatchManyOptions(inputs=list(args.inputs), out=args.out, manifest=args.manifest,
                            batch_args=batch_args, scheduler=args.scheduler, workers=args.workers,
                            retries=args.retries, overwrite=args.overwrite, timeout=args.timeout,
                            dashboard_address=args.dashboard_address,
                            batch_script=args.batch_script or DEFAULT_BATCH_SCRIPT,
                            blender=args.blender, progress=not args.quiet)
    report = run_batch_many(opts)
    return 1 if report["counts"]["failed"] else 0
