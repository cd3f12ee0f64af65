"""``evaluate``: SpecGen on the corpus' held-out test split (paper §4.1 protocol, distant lights).

For each test material: render its canonical sphere input image, generate the spectral BRDF
from it, and render the sphere from the predicted table and from the true analytic BRDF under
the protocol's distant lights at its 20 wavelengths (:mod:`specgen_addon.evaluation.protocol`).
PSNR/SSIM come from :mod:`specgen_addon.render.metrics` (one normalisation used project-wide).

With ``refine`` (the CLI's default) the table is also refined to its input photo
(:func:`specgen_addon.generate.refine.refine_brdf`, canonical lighting) and scored the same way, and both
tables' *self-reproduction* is reported: rendered under the input's lighting against the input
image, RGB PSNR and mean ΔE2000 (every fidelity figure comes with it).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from specgen_addon.train.augment import displaced_input
from specgen_addon.brdf.formats import load_brdf
from specgen_addon.common.errors import SpecGenError
from specgen_addon.corpus import generate_corpus
from specgen_addon.corpus.families import FAMILY_NAMES
from specgen_addon.corpus.generate import FAMILY_MIX, generate_mixed_corpus, material_family
from specgen_addon.corpus.spectra_sources import SPLITS
from specgen_addon.evaluation.protocol import (CORPUS_SEED, CORPUS_SIZE, DISTANT_LIGHTS, WAVELENGTHS_NM,
                                               input_lighting_under, input_under_environment)
from specgen_addon.evaluation.self_reproduction import self_reproduction as reproduce
from specgen_addon.generate.refine import RefineOptions, refine_brdf
from specgen_addon.model.runtime.inference import generate_brdf
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.render import (environment_maps as lighting, metrics, render_rgb, render_spectral,
                                  sphere_geometry)

RESOLUTION = 128


def evaluate_test_split(weights: str | Path | None = None, limit: int | None = None,
                        backend: str = "torch", resolution: int = RESOLUTION,
                        progress: Callable[[float], None] | None = None,
                        refine: bool = False) -> dict[str, Any]:
    """Per-material and mean PSNR (dB) / SSIM over the test split; returns a JSON-able dict
    (with ``refine``: also the refined table's PSNR/SSIM and both tables' self-reproduction)."""
    test = [m for m in generate_corpus(CORPUS_SIZE, CORPUS_SEED) if m.split == "test"]
    if limit is not None:
        test = test[:limit]
    geo = sphere_geometry(resolution)
    rows = []
    t_infer = []
    for i, mat in enumerate(test):
        image = input_image.render_input(mat)
        t0 = time.perf_counter()
        table = generate_brdf(image, weights=weights, wavelengths_nm=WAVELENGTHS_NM, backend=backend)
        t_infer.append(time.perf_counter() - t0)
        gt = render_spectral(mat, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
        res = metrics.spectral_metrics(gt, pred, geo.mask)
        row = {"material": mat.name, "kind": mat.kind, "psnr": float(res.psnr_mean),
               "ssim": float(res.ssim_mean)}
        if refine:
            fit = refine_brdf(table, image, options=RefineOptions(clip_level=None))
            ref = render_spectral(fit.table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).spectral
            res_r = metrics.spectral_metrics(gt, ref, geo.mask)
            row |= {"psnr_refined": float(res_r.psnr_mean), "ssim_refined": float(res_r.ssim_mean),
                    "self_psnr_network": fit.before.psnr_db, "self_de_network": fit.before.delta_e2000,
                    "self_psnr_refined": fit.after.psnr_db, "self_de_refined": fit.after.delta_e2000}
        rows.append(row)
        if progress is not None:
            progress((i + 1) / len(test))
    psnr = np.array([r["psnr"] for r in rows])
    ssim = np.array([r["ssim"] for r in rows])
    means = {f"{k}_mean": float(np.mean([r[k] for r in rows])) for k in
             ("psnr_refined", "ssim_refined", "self_psnr_network", "self_psnr_refined",
              "self_de_network", "self_de_refined")
             if rows and all(r.get(k) is not None for r in rows)}
    return {"materials": rows, "psnr_mean": float(psnr.mean()), "ssim_mean": float(ssim.mean()), **means,
            "psnr_median": float(np.median(psnr)), "n": len(rows),
            "wavelengths_nm": [float(w) for w in WAVELENGTHS_NM], "resolution": resolution,
            "weights": str(weights) if weights else "default", "backend": backend,
            "mean_infer_seconds": float(np.mean(t_infer)) if t_infer else None,
            "metrics": getattr(metrics, "NORMALISATION_TEXT", "")}


def format_results(res: dict[str, Any]) -> str:
    """A plain table: material, kind, PSNR, SSIM (network alone; refined and self-reproduction
    network → refined when present), then the means."""
    refined = "psnr_refined_mean" in res
    head = f"{'material':<12} {'kind':<20} {'PSNR dB':>8} {'SSIM':>7}"
    if refined:
        head += f" {'refined dB':>10} {'SSIM':>7}   {'self-reproduction dB (ΔE2000)':<34}"
    lines = [head]

    def tail(r: dict, suffix: str = "") -> str:
        if not refined:
            return ""
        de = "" if r[f"self_de_network{suffix}"] is None else \
            f" ({r[f'self_de_network{suffix}']:.2f} → {r[f'self_de_refined{suffix}']:.2f})"
        return (f" {r[f'psnr_refined{suffix}']:10.2f} {r[f'ssim_refined{suffix}']:7.4f}   "
                f"{r[f'self_psnr_network{suffix}']:.1f} → {r[f'self_psnr_refined{suffix}']:.1f}{de}")

    for r in res["materials"]:
        lines.append(f"{r['material']:<12} {r['kind']:<20} {r['psnr']:8.2f} {r['ssim']:7.4f}" + tail(r))
    lines.append(f"{'mean':<12} {'':<20} {res['psnr_mean']:8.2f} {res['ssim_mean']:7.4f}" + tail(res, "_mean")
                 + f"   ({res['n']} test materials, {len(res['wavelengths_nm'])} bands, distant lights)")
    return "\n".join(lines)


# --- per-family evaluation ------------------------------------------------------------

#: The mixed corpus the default model trains on (configs/default.json), whose test split is scored.
MIXED_CORPUS_SIZE = 2900
MIXED_CORPUS_SEED = 0


def mixed_test_materials(per_family: int, families: list[str] | None = None) -> list:
    """The first ``per_family`` test materials of each family of the mixed corpus (corpus order)."""
    return mixed_split_materials(per_family, families, "test")


def mixed_split_materials(per_family: int, families: list[str] | None = None, split: str = "test",
                          skip: int = 0) -> list:
    """``per_family`` materials of ``split`` (train, val or test) of each family of the mixed corpus,
    after its first ``skip`` (fresh materials for a new study), in corpus order (settings are chosen on
    ``val``, figures reported on ``test``)."""
    if split not in SPLITS:
        raise SpecGenError(f"unknown split {split!r} (choose from {', '.join(SPLITS)})")
    wanted = list(FAMILY_MIX if families is None else families)
    for family in wanted:   # the mixed corpus draws only the default mix's families
        if family not in FAMILY_MIX:
            raise SpecGenError(
                f"family {family!r} is not in the default training mix ({', '.join(FAMILY_MIX)}), so the "
                "mixed corpus holds none of it to score" if family in FAMILY_NAMES else
                f"unknown family {family!r} (choose from {', '.join(FAMILY_MIX)})")
    out, count = [], {f: 0 for f in wanted}
    for m in generate_mixed_corpus(MIXED_CORPUS_SIZE, MIXED_CORPUS_SEED):
        f = material_family(m)
        if m.split == split and f in count and count[f] < skip + per_family:
            if count[f] >= skip:
                out.append(m)
            count[f] += 1
    return out


def antialiased_input(brdf, shift_px: float = 0.0, supersample: int = 4, border_px: int = 16,
                      size: int | None = None) -> np.ndarray:
    """The canonical input of ``brdf`` as a camera or an antialiased render takes it: rendered at
    ``supersample``× the size and box-filtered (each pixel the mean over its area), inside a black
    border of ``border_px``, moved by ``shift_px`` pixels right and down (rounded to
    1/``supersample`` of a pixel)."""
    size = int(size or input_image.CANONICAL_SIZE)
    hi = input_image.render_input(brdf, size=size * supersample)
    k, b = int(round(shift_px * supersample)), border_px * supersample
    padded = np.pad(hi, ((b + k, b - k), (b + k, b - k), (0, 0)))
    n = padded.shape[0] // supersample
    return padded.reshape(n, supersample, n, supersample, 3).mean(axis=(1, 3)).astype(np.float32)


def evaluate_families(weights: str | Path | None = None, per_family: int = 4, envs: bool = True,
                      rgl_dir: str | Path | None = None, backend: str = "torch",
                      resolution: int = RESOLUTION, families: list[str] | None = None,
                      progress: Callable[[float], None] | None = None,
                      input_env: str | None = None, input_shift_px: float = 0.0,
                      input_antialias: bool = False, self_reproduction: bool = True,
                      split: str = "test") -> dict[str, Any]:
    """PSNR/SSIM per family of the mixed test split, network alone (no refinement), each family
    with its self-reproduction (the photo is the measurement).

    ``split``: ``"test"`` (held out: the figures docs/model-card.md's targets are on), or ``"train"`` /
    ``"val"`` for the same protocol on other materials, e.g. to tell how well the network fits the
    materials it was trained on from how well it generalises.

    Scenes: the protocol's distant lights and, with ``envs``, the two held-out environment maps
    (:data:`specgen_addon.render.environment_maps.HELDOUT_ENVS`). The input is the canonical sphere, or with
    ``input_env`` the sphere photographed under that map
    (:func:`specgen_addon.evaluation.protocol.input_under_environment`) and the network not told:
    the canonical-input score says how well it fits, this one how robust it is to a user's lighting.
    ``input_shift_px``: the input sphere moved by that many pixels right and down inside a black
    border (:func:`displaced_input`) before the pipeline finds and crops it, as in a user's photo.
    ``input_antialias``: the canonical input area-sampled instead (:func:`antialiased_input`, moved
    by ``input_shift_px``), as a camera or an antialiased render takes it.
    ``rgl_dir``: real RGL RGB files (``*.bsdf``) scored in linear sRGB under the distant lights
    (the project renderer's slice assignment: the light direction selects the measured slice).
    ``self_reproduction``: also render each predicted table under the lighting its input photo was
    taken in and score it against that photo (RGB PSNR dB, mean ΔE2000;
    :func:`specgen_addon.evaluation.self_reproduction.self_reproduction`). Not for a moved or
    area-sampled input, whose photo is not the renderer's frame.
    """
    geo = sphere_geometry(resolution)
    scenes: list[tuple[str, dict]] = [("distant", {"lights": DISTANT_LIGHTS})]
    if envs:
        scenes += [(f"env-{e}", {"environment": lighting.load_environment(e)}) for e in lighting.HELDOUT_ENVS]
    mats = mixed_split_materials(per_family, families, split)
    rgl_files = sorted(Path(rgl_dir).glob("*.bsdf")) if rgl_dir is not None and Path(rgl_dir).is_dir() else []
    total = len(mats) + len(rgl_files)
    def input_of(brdf) -> np.ndarray:
        if input_antialias:
            return antialiased_input(brdf, input_shift_px)
        if input_env is None:
            image = input_image.render_input(brdf)
        else:
            image = input_under_environment(brdf, input_env)
        return displaced_input(image, input_shift_px) if input_shift_px else image

    photo_lighting = None
    if self_reproduction and not input_shift_px and not input_antialias:
        photo_lighting = InputLighting() if input_env is None else input_lighting_under(input_env)

    def scored_reproduction(table, photo: np.ndarray) -> dict[str, Any]:
        if photo_lighting is None:
            return {}
        rep = reproduce(table, photo, photo_lighting)
        return {"self_psnr": rep.psnr_db, "self_de": rep.delta_e2000}

    rows = []
    for i, mat in enumerate(mats):
        photo = input_of(mat)
        table = generate_brdf(photo, weights=weights, wavelengths_nm=WAVELENGTHS_NM, backend=backend)
        row: dict[str, Any] = {"material": mat.name, "family": material_family(mat), "kind": mat.kind,
                               "network": Path(table.metadata["weights"]).name,  # which network served
                               **scored_reproduction(table, photo)}
        for label, kw in scenes:
            gt = render_spectral(mat, geo, wavelengths_nm=WAVELENGTHS_NM, **kw).spectral
            pred = render_spectral(table, geo, wavelengths_nm=WAVELENGTHS_NM, **kw).spectral
            res = metrics.spectral_metrics(gt, pred, geo.mask)
            row[f"psnr_{label}"], row[f"ssim_{label}"] = float(res.psnr_mean), float(res.ssim_mean)
            # oracle diagnostic: how much of the error one brightness factor explains
            row[f"psnr_brightness_fitted_{label}"], row[f"brightness_{label}"] = \
                metrics.brightness_fitted_psnr(gt, pred, geo.mask)
            # and how much one overall colour (a smooth spectral gain) explains
            row[f"psnr_colour_fitted_{label}"] = metrics.colour_fitted_psnr(gt, pred, WAVELENGTHS_NM, geo.mask)[0]
        rows.append(row)
        if progress is not None:
            progress((i + 1) / total)
    for j, path in enumerate(rgl_files):
        brdf = load_brdf(path)
        photo = input_of(brdf)
        table = generate_brdf(photo, weights=weights, wavelengths_nm=WAVELENGTHS_NM, backend=backend)
        gt = render_rgb(brdf, geo, lights=DISTANT_LIGHTS).rgb
        pred = render_spectral(table, geo, lights=DISTANT_LIGHTS, wavelengths_nm=WAVELENGTHS_NM).rgb
        res = metrics.spectral_metrics(gt, pred, geo.mask)
        rows.append({"material": path.stem, "family": "rgl (real, RGB)", "kind": "measured",
                     "network": Path(table.metadata["weights"]).name,
                     "psnr_distant": float(res.psnr_mean), "ssim_distant": float(res.ssim_mean),
                     **scored_reproduction(table, photo)})
        if progress is not None:
            progress((len(mats) + j + 1) / total)
    labels = [lab for lab, _ in scenes]
    by_family: dict[str, dict[str, float]] = {}
    for fam in dict.fromkeys(r["family"] for r in rows):
        sel = [r for r in rows if r["family"] == fam]
        by_family[fam] = {"n": len(sel), **{f"{k}_{lab}": float(np.mean([r[f"{k}_{lab}"] for r in sel]))
                                          for lab in labels for k in ("psnr", "ssim")
                                          if all(f"{k}_{lab}" in r for r in sel)},
                          **_reproduction_means(sel)}
    synth = [r for r in rows if r["kind"] != "measured"]
    means = {f"{k}_{lab}": float(np.mean([r[f"{k}_{lab}"] for r in synth]))
             for lab in labels for k in ("psnr", "ssim", "psnr_brightness_fitted", "psnr_colour_fitted")
             if synth and all(f"{k}_{lab}" in r for r in synth)}
    means |= _reproduction_means(synth)
    return {"materials": rows, "families": by_family, "means": means, "scenes": labels,
            "per_family": per_family, "split": split, "resolution": resolution,
            "input": input_env or "canonical",
            "input_shift_px": input_shift_px, "input_antialias": input_antialias,
            "weights": str(weights) if weights else "default: the shipped pair, chosen by each sphere's cut",
            "backend": backend, "corpus": {"size": MIXED_CORPUS_SIZE, "seed": MIXED_CORPUS_SEED},
            "metrics": getattr(metrics, "NORMALISATION_TEXT", "")}


def _reproduction_means(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Mean self-reproduction PSNR (dB) and ΔE2000 of rows that all carry them (else nothing)."""
    return {k: float(np.mean([r[k] for r in rows])) for k in ("self_psnr", "self_de")
            if rows and all(r.get(k) is not None for r in rows)}


def family_rows(res: dict[str, Any], mean_label: str = "mean (synthetic)") -> tuple[list[str], list[list[str]]]:
    """(header, rows) of :func:`evaluate_families`' summary: PSNR dB / SSIM per family and scene
    (synthetic families first, then the real files), then the mean over the synthetic materials;
    with a last column of the self-reproduction (photo RGB PSNR dB / ΔE2000) where it was scored."""
    labels = res["scenes"]
    reproduced = any("self_psnr" in s for s in res["families"].values())
    header = ["family", "n"] + [f"{lab} PSNR / SSIM" for lab in labels]
    if reproduced:
        header.append("self-reproduction dB / ΔE2000")

    def cells(s: dict) -> list[str]:
        out = [f"{s[f'psnr_{lab}']:.2f} / {s[f'ssim_{lab}']:.4f}" if f"psnr_{lab}" in s else "—" for lab in labels]
        if reproduced:
            out.append(f"{s['self_psnr']:.2f} / {s['self_de']:.2f}" if "self_psnr" in s and "self_de" in s
                       else "—")
        return out

    # a fixed order (a cached JSON comes back with sorted keys): synthetic families, then real files
    order = sorted(res["families"], key=lambda f: (f.startswith("rgl"), f))
    rows = [[fam, str(res["families"][fam]["n"])] + cells(res["families"][fam]) for fam in order]
    if res.get("means"):
        n = sum(s["n"] for f, s in res["families"].items() if not f.startswith("rgl"))
        rows.append([mean_label, str(n)] + cells(res["means"]))
    return header, rows


def format_family_results(res: dict[str, Any]) -> str:
    """:func:`family_rows` as a plain fixed-width table for the terminal."""
    header, rows = family_rows(res)
    lead = [] if res.get("input", "canonical") == "canonical" else \
        [f"input: the sphere under {res['input']!r}, the network not told"]
    if res.get("split", "test") != "test":
        lead.append(f"materials of the {res['split']!r} split, not the held-out test split")
    means = res.get("means", {})
    tail = []
    for what, key in (("brightness", "psnr_brightness_fitted"), ("colour (a smooth spectral gain)", "psnr_colour_fitted")):
        fitted = [f"{lab} {means[f'{key}_{lab}']:.2f} dB" for lab in res["scenes"] if f"{key}_{lab}" in means]
        if fitted:
            tail.append(f"with each prediction's {what} fitted to the truth (oracle diagnostic): {', '.join(fitted)}")
    widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]
    return "\n".join(lead + ["  ".join(cell.ljust(w) if c == 0 else cell.rjust(w) for c, (cell, w) in
                                        enumerate(zip(r, widths))) for r in [header, *rows]] + tail)
