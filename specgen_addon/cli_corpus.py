"""CLI command ``corpus``: generate the synthetic spectral BRDF corpus manifest (and tables)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .corpus import find_material, generate_corpus, load_manifest, save_manifest
from .errors import OutputExistsError, SpecGenError
from .progress import progress_bar
from .spectra import DEFAULT_BAND_COUNT, DEFAULT_RANGE_NM, wavelength_grid

MANIFEST_NAME = "manifest.json"


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("corpus", help="generate the synthetic spectral BRDF corpus (manifest.json)",
                       description="Generate N physically based spectral materials, deterministic by "
                                   "seed, with train/val/test splits made by spectrum source; write "
                                   "OUT/manifest.json and optionally MERL-grid tables of some.")
    p.add_argument("--n", type=int, default=200, help="number of materials (default 200)")
    p.add_argument("--seed", type=int, default=0, help="corpus seed (default 0)")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--tabulate", metavar="NAME", action="append", default=[],
                   help="also write OUT/NAME.npz (MERL grid, spectral); repeatable")
    p.add_argument("--bands", type=int, default=DEFAULT_BAND_COUNT,
                   help=f"wavelength bands of tables over {DEFAULT_RANGE_NM[0]:g}–"
                        f"{DEFAULT_RANGE_NM[1]:g} nm (default {DEFAULT_BAND_COUNT})")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    if args.n < 1:
        raise SpecGenError(f"--n must be at least 1, got {args.n}")
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise SpecGenError(f"{out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    with progress_bar("corpus", enabled=not args.quiet) as update:
        materials = generate_corpus(args.n, args.seed, progress=update)
    manifest = out / MANIFEST_NAME
    if manifest.exists() and not args.overwrite:
        try:
            same = load_manifest(manifest) == materials
        except SpecGenError:
            same = False
        if not same:
            raise OutputExistsError(f"{manifest}: exists with other materials (pass --overwrite)")
    else:
        save_manifest(manifest, materials, seed=args.seed, overwrite=args.overwrite)
    counts = {s: sum(m.split == s for m in materials) for s in ("train", "val", "test")}
    print(f"{manifest}: {len(materials)} materials "
          f"({', '.join(f'{k} {v}' for k, v in counts.items())})")
    wavelengths = wavelength_grid(*DEFAULT_RANGE_NM, args.bands)
    for name in args.tabulate:
        material = find_material(materials, name)
        with progress_bar(f"tabulate {name}", enabled=not args.quiet) as update:
            table = material.tabulate(wavelengths, progress=update)
        path = table.save(out / f"{name}.npz", overwrite=args.overwrite)
        print(f"{path}: {material.kind}, {args.bands} bands")
    return 0
