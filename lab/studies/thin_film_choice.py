"""Can the photo itself choose between the refined network and the thin-film fit?

A `--model auto` would run both on the photo and keep the one that reproduces it better (the photo is
the measurement). This measures whether that choice is right: per held-out material of the mixed
split, the self-reproduction PSNR (RGB, on the photo) of the refined network's table and of the
thin-film fit, and each table's spectral PSNR under the protocol's distant lights (the truth).

``--photo canonical`` uses the canonical input (rendered with the refinement operator's own
environment samples: a best case for refinement, docs/refinement.md); ``--photo independent`` renders
the photo with other samples (seed 1, 224 directions per pixel), as a real photo shares none.

    cd bench && python thin_film_choice.py --per-family 1 --photo independent
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np



def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=1, help="held-out materials per family (default 1)")
    ap.add_argument("--photo", choices=("canonical", "independent"), default="independent",
                    help="the photo: the canonical input, or rendered with other samples (default)")
    a = ap.parse_args(argv)
    if a.per_family < 1:
        ap.error("--per-family must be ≥ 1")

    from off_grid_refine import independent_photo, truth_scorer
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.evaluation.protocol import WAVELENGTHS_NM
    from specgen_addon.generate.pipeline import generate
    from specgen_addon.render import EnvSampling
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    sampling = replace(EnvSampling().scaled(2.0), seed=1)
    right = 0
    rows = mixed_test_materials(a.per_family)
    print("material kind: self-reproduction refined / film (dB) → choice; distant PSNR refined / film (dB)")
    for mat in rows:
        t0 = time.perf_counter()
        photo = (input_image.render_input(mat) if a.photo == "canonical"
                 else independent_photo(mat, sampling)).astype(np.float64)
        score = truth_scorer(mat, 64)

        net = generate(photo, wavelengths_nm=WAVELENGTHS_NM)
        film = generate(photo, wavelengths_nm=WAVELENGTHS_NM, model="thin-film")
        self_net, self_film = net.refinement.after.psnr_db, film.film_fit.reproduction.psnr_db
        true_net, true_film = score(net.table), score(film.table)
        chose_film = self_film > self_net
        right += chose_film == (true_film > true_net)
        print(f"{mat.name} {mat.kind}: {self_net:.1f} / {self_film:.1f} → "
              f"{'film' if chose_film else 'network'}; {true_net:.2f} / {true_film:.2f} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    print(f"the photo chose the better table for {right} of {len(rows)} materials")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
