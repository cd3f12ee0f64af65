"""CLI commands on BRDF files: ``info`` (metadata) and ``tabulate`` (to the SpecGen table format)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from specgen_addon.common.errors import SpecGenError
from specgen_addon.brdf.formats import detect_format, load_brdf, tabulate_file
from specgen_addon.common.progress import progress_bar
from specgen_addon.spectral.spectra import DEFAULT_RANGE_NM, DEFAULT_BAND_COUNT, wavelength_grid
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.brdf.formats.export import check_output, write_output


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="print a BRDF file's metadata (RGL .bsdf, MERL .binary, .npz table)")
    p.add_argument("file", type=Path, metavar="FILE",
                   help="BRDF file: RGL .bsdf, MERL .binary or SpecGen .npz (format read from its header)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=run_info)

    p = sub.add_parser("tabulate", help="tabulate an RGL or MERL file onto the MERL grid (.npz table)")
    p.add_argument("file", type=Path, metavar="FILE",
                   help="BRDF file to tabulate: RGL .bsdf (spectral or RGB), MERL .binary or SpecGen .npz "
                        "(the last two are on the MERL grid already and are only rewritten)")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output: .npz (compact material; full table with --full-table), .bsdf or .binary")
    p.add_argument("--full-table", action="store_true",
                   help="write the full float32 table instead of the compact material file")
    p.add_argument("--wl-min", type=float, default=DEFAULT_RANGE_NM[0],
                   help="first wavelength, nm (default %(default)g)")
    p.add_argument("--wl-max", type=float, default=DEFAULT_RANGE_NM[1],
                   help="last wavelength, nm (default %(default)g)")
    p.add_argument("--bands", type=int, default=DEFAULT_BAND_COUNT,
                   help="wavelength count for spectral files, 1–128 (default %(default)s; RGB files keep R, G, B)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_tabulate)


def describe(path: Path) -> dict:
    """Metadata of a BRDF file as a plain dict."""
    kind = detect_format(path)
    brdf = load_brdf(path)
    info: dict = {"file": str(path), "format": kind}
    if isinstance(brdf, BRDFTable):
        info.update(kind="spectral" if brdf.is_spectral else "rgb", channels=len(brdf.channels),
                    grid=list(brdf.values.shape[:3]), metadata=brdf.metadata)
        if brdf.is_spectral:
            w = [float(x) for x in brdf.wavelengths]
            info.update(bands=len(w), wavelength_range_nm=[w[0], w[-1]], wavelengths_nm=w)
    else:
        info.update(brdf.info() if hasattr(brdf, "info") else {})
    return info


def run_info(args: argparse.Namespace) -> int:
    info = describe(args.file)
    if args.json:
        print(json.dumps(info, indent=2, default=str))
    else:
        for key, value in info.items():
            print(f"{key:>16}: {value}")
    return 0


def run_tabulate(args: argparse.Namespace) -> int:
    check_output(args.out)
    if args.out.exists() and not args.overwrite:
        raise SpecGenError(f"{args.out}: already exists (use --overwrite)")
    wavelengths = wavelength_grid(args.wl_min, args.wl_max, args.bands)
    with progress_bar(f"tabulating {args.file.name}", enabled=not args.quiet) as update:
        table = tabulate_file(args.file, wavelengths, progress=update)
    print(write_output(table, args.out, overwrite=args.overwrite, full_table=args.full_table)
          + f": {'spectral' if table.is_spectral else 'RGB'}, {table.n_channels} channels")
    return 0
