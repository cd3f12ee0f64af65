"""Turn a BRDF file into what ``batch.py`` takes: ``python -m specgen_addon.scale.prepare SRC DIR``.

* a spectral SpecGen table (``.npz``) is used as it is (``--brdf``);
* a spectral RGL ``.bsdf`` is tabulated onto the MERL grid (380–780 nm, 21 bands) into
  ``DIR/<stem>.npz`` (``--brdf``);
* an RGB BRDF (MERL ``.binary``, RGB ``.bsdf`` or ``.npz``) has no spectrum to render: SpecGen
  generates one from the photo the material would give, its canonical sphere render
  (:func:`specgen_addon.photo.sphere_image.render_input`), written to ``DIR/<stem>.exr`` (``--image``).

Prints one line ``brdf PATH`` or ``image PATH``. A bad file exits 2 with one line on stderr, like
``batch.py``, so the worker reports it without retrying.
"""

from __future__ import annotations

import sys
from pathlib import Path

from specgen_addon.brdf.formats import load_brdf, tabulate_file
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.spectral.spectra import wavelength_grid

EXIT_BAD_INPUT = 2


def prepare(src: Path, work: Path) -> tuple[str, Path]:
    """(``"brdf"`` or ``"image"``, path to hand to ``batch.py``) for the BRDF file ``src``."""
    brdf = load_brdf(src)
    spectral = bool(getattr(brdf, "is_spectral", False))
    work.mkdir(parents=True, exist_ok=True)
    if spectral and isinstance(brdf, BRDFTable):
        return "brdf", src
    if spectral:
        table = tabulate_file(src, wavelength_grid())
        dst = work / f"{src.stem}.npz"
        table.save(dst, overwrite=True)
        return "brdf", dst

    dst = work / f"{src.stem}.exr"
    input_image.write_exr_rgb(dst, input_image.render_input(brdf), overwrite=True)
    return "image", dst


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python -m specgen_addon.scale.prepare BRDF_FILE WORK_DIR", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        kind, path = prepare(Path(argv[0]), Path(argv[1]))
    except SpecGenError as exc:
        print(f"prepare: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"{kind} {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
