"""CLI command ``corpus``: generate the synthetic spectral BRDF corpus manifest (and tables)."""

from __future__ import annotations

import argparse
from pathlib import Path

from specgen_addon.corpus import find_material, generate_corpus, load_manifest, save_manifest
from specgen_addon.common.errors import OutputExistsError, SpecGenError
from specgen_addon.common.limits import check_number
from specgen_addon.common.progress import progress_bar
from specgen_addon.spectral.spectra import DEFAULT_BAND_COUNT, DEFAULT_RANGE_NM, wavelength_grid
from specgen_addon.common.cache import cache_root
from specgen_addon.corpus.families import FAMILY_NAMES
from specgen_addon.corpus.generate import FAMILY_MIX, check_mix, generate_mixed_corpus, material_family

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
    p.add_argument("--families", default="classic", metavar="MIX",
                   help="family mix: 'classic' (default: classic materials only, i.e. plastics and metals, "
                        "some clear-coated; docs/dev/corpus.md), 'default' (the training "
                        "mix of configs/default.json), or NAME=WEIGHT,... over "
                        f"{', '.join(FAMILY_NAMES)}")
    p.add_argument("--inputs", action="store_true",
                   help="also render the train/val materials' training-input lighting components into "
                        "the cache (resumable: only missing renders are made)")
    p.add_argument("--workers", type=int, default=2, help="render processes for --inputs (default 2)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
    return p


#: Largest corpus the command accepts (a manifest of this size is ~100 MB).
MAX_MATERIALS = 50_000


def parse_mix(text: str) -> dict[str, float] | None:
    """``--families`` → mix (None: the classic recipe); SpecGenError if malformed or unknown."""
    if text == "classic":
        return None
    if text == "default":
        return dict(FAMILY_MIX)
    mix: dict[str, float] = {}
    for part in text.split(","):
        name, _, weight = part.partition("=")
        try:
            mix[name.strip()] = float(weight) if weight else 1.0
        except ValueError:
            raise SpecGenError(f"--families: weight {weight!r} of {name!r} is not a number") from None
    check_mix(mix)
    return mix


def run(args: argparse.Namespace) -> int:
    if not 1 <= args.n <= MAX_MATERIALS:
        raise SpecGenError(f"--n must be between 1 and {MAX_MATERIALS}, got {args.n}")
    if args.seed < 0:
        raise SpecGenError(f"--seed must be ≥ 0, got {args.seed}")
    if not 1 <= args.bands <= 401:
        raise SpecGenError(f"--bands must be between 1 and 401, got {args.bands}")
    check_number("workers", args.workers)
    mix = parse_mix(args.families)
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise SpecGenError(f"{out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    with progress_bar("corpus", enabled=not args.quiet) as update:
        if mix is None:
            materials = generate_corpus(args.n, args.seed, progress=update)
        else:
            materials = generate_mixed_corpus(args.n, args.seed, mix, progress=update)
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
    if mix is not None:
        fams = sorted({material_family(m) for m in materials})
        print("families (train/val/test): " + ", ".join(
            f"{f} {'/'.join(str(sum(material_family(m) == f and m.split == s for m in materials)) for s in ('train', 'val', 'test'))}"
            for f in fams))
    if args.inputs:
        _render_inputs(materials, args.workers, not args.quiet)
    wavelengths = wavelength_grid(*DEFAULT_RANGE_NM, args.bands)
    for name in args.tabulate:
        material = find_material(materials, name)
        with progress_bar(f"tabulate {name}", enabled=not args.quiet) as update:
            table = material.tabulate(wavelengths, progress=update)
        path = table.save(out / f"{name}.npz", overwrite=args.overwrite)
        print(f"{path}: {material.kind}, {args.bands} bands")
    return 0


def _render_inputs(materials, workers: int, show: bool) -> None:
    """Render the train/val materials' lighting components into the training cache (resumable)."""
    import time

    from specgen_addon.train.data import TrainingMaterial
    from specgen_addon.train.lighting_mix import ComponentCache

    cache = ComponentCache(cache_root() / "train-data")
    mats = [TrainingMaterial(m.name, m, True, m.split) for m in materials if m.split != "test"]
    todo = cache.missing(mats)
    t0 = time.perf_counter()
    with progress_bar("input renders", enabled=show) as update:
        cache.fill(mats, workers=workers, progress=update)
    print(f"{cache.cache_dir}: {len(mats)} materials' training inputs ({len(todo)} rendered now in "
          f"{time.perf_counter() - t0:.0f} s, {len(mats) - len(todo)} cached)")
