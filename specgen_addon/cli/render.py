"""CLI command ``render-input``: the canonical sphere input image of a material (EXR + PNG)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.progress import progress_bar
from specgen_addon.brdf.formats import load_brdf
from specgen_addon.corpus import find_material, generate_corpus, load_manifest
from specgen_addon.photo import sphere_image as input_image

#: Corpus used to resolve material names and indices (the project's standard corpus).
CORPUS_SIZE = 200
CORPUS_SEED = 0


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "render-input", help="render a material's canonical sphere input image (EXR + PNG)",
        description="Render the image SpecGen consumes: a 128×128 sphere of MATERIAL under the "
                    "canonical lighting (studio map + D65 key light, exposure 0.5), written as a "
                    "linear EXR and an 8-bit sRGB PNG beside it (see docs/dev/renderer.md).")
    p.add_argument("material", metavar="MATERIAL",
                   help="BRDF file (MERL .binary, RGL .bsdf, SpecGen .npz), or a corpus material "
                        "name (e.g. mat0007) or index")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output .exr or .png (the other one is written beside it)")
    p.add_argument("--size", type=int, default=128, help="image size in pixels (default 128)")
    p.add_argument("--manifest", type=Path, default=None,
                   help="corpus manifest.json to resolve MATERIAL in (default: the standard "
                        f"corpus, n={CORPUS_SIZE}, seed={CORPUS_SEED})")
    p.add_argument("--variant", type=int, default=0,
                   help="training lighting variant (0 = canonical, the default)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
    return p


def resolve_material(spec: str, manifest: Path | None = None):
    """A BRDF object from a file path, or a corpus material by name or index."""
    path = Path(spec)
    if path.is_file():
        return load_brdf(path)

    if manifest is not None:
        materials = load_manifest(manifest)
    else:
        m = re.fullmatch(r"(?:mat)?(\d+)", spec)
        n = int(m.group(1)) + 1 if m else CORPUS_SIZE  # the corpus is deterministic by prefix
        materials = generate_corpus(max(n, 1), CORPUS_SEED)
    if spec.isdigit():
        index = int(spec)
        if index >= len(materials):
            raise SpecGenError(f"corpus index {index} out of range (0–{len(materials) - 1})")
        return materials[index]
    if not path.suffix and "/" not in spec:
        return find_material(materials, spec)
    raise SpecGenError(f"{spec}: no such BRDF file, and not a corpus material name or index")


def run(args: argparse.Namespace) -> int:
    input_image.output_paths(args.out, args.overwrite)  # fail before rendering
    if args.size < 16:
        raise SpecGenError(f"--size must be at least 16, got {args.size}")
    brdf = resolve_material(args.material, args.manifest)
    with progress_bar("render-input", enabled=not args.quiet) as update:
        if args.variant == 0:
            rgb = input_image.render_input(brdf, args.size, progress=update)
        else:
            rgb = input_image.render_training_input(brdf, args.variant, args.size)
            update(1.0)
    written = input_image.save_input(rgb, args.out, overwrite=args.overwrite)
    print(" ".join(str(p) for p in written))
    return 0
