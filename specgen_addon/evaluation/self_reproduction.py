"""Self-reproduction and novel-lighting study of the refinement (principle: the photo is the
measurement).

For a material (a held-out corpus material, or a real RGL file) and an input lighting:

1. its photo is rendered under that lighting (the reference renderer, as every input is);
2. the network generates a table from the photo (brought to the canonical white level first);
3. the refinement fits the table to the photo under the same lighting;
4. both tables are rendered under the input lighting (self-reproduction: RGB PSNR, ΔE2000 against
   the photo) and, for novel lighting, under the protocol's distant lights and the held-out maps
   (spectral PSNR against the true BRDF; RGB for RGB-only files).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from specgen_addon.render import metrics
from specgen_addon.brdf.formats import load_brdf
from specgen_addon.evaluation.photo_fit import observed_pixels
from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM, test_materials
from specgen_addon.generate.refine import RefineOptions, refine_brdf
from specgen_addon.model.runtime.inference import generate_brdf
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.render import Scene, sphere_geometry
from specgen_addon.render.environment_maps import load_environment
from specgen_addon.render.photo_reproduction import reproduction
from specgen_addon.render.sampling import EnvSampling
from specgen_addon.spectral import spectra

RESOLUTION = 128


def photo_under(brdf, lighting) -> np.ndarray:
    """The input photo of ``brdf`` under ``lighting`` (linear sRGB, canonical sphere crop)."""
    if lighting.is_canonical:
        return input_image.render_input(brdf).astype(np.float64)
    scene = lighting.scene(input_image.CANONICAL_SIZE)
    return input_image.photo_in_scene(brdf, scene, lighting.image_exposure).astype(np.float64)


def self_reproduction(brdf, photo: np.ndarray, lighting) -> Any:
    """How well ``brdf`` reproduces ``photo``: rendered under ``lighting`` (an
    :class:`~specgen_addon.photo.photo_lighting.InputLighting`) exactly as an input photo is made, against
    the photo (linear sRGB, canonical sphere crop), over the sphere without its grazing rim as the
    refinement scores it. Returns a :class:`specgen_addon.render.photo_reproduction.Reproduction` (RGB PSNR in
    dB, mean ΔE2000). A table renders at its own bands, an analytic material at the default ones."""
    photo = np.asarray(photo, np.float64)
    scene = lighting.scene(photo.shape[0])
    wl = getattr(brdf, "wavelengths", None)
    wl = spectra.DEFAULT_WAVELENGTHS_NM if wl is None else wl
    rendered = np.clip(scene.render_spectral(brdf, wl).rgb, 0.0, None) * lighting.image_exposure
    seen = observed_pixels(scene)
    return reproduction(photo.reshape(-1, 3)[seen], rendered.reshape(-1, 3)[seen])


def _novel_scores(truth, network, refined, rgb_only: bool, envs: Sequence[str]) -> dict[str, dict]:
    """Spectral (or RGB) PSNR of network and refined tables against the truth in novel lighting."""
    geo = sphere_geometry(RESOLUTION)
    scenes = {"distant": Scene(geo, DISTANT_LIGHTS)}
    for env in envs:
        scenes[f"env-{env}"] = Scene(geo, [], load_environment(env), sampling=EnvSampling())
    out = {}
    for name, sc in scenes.items():
        if rgb_only:
            gt = sc.render_rgb(truth).rgb
            imgs = {k: sc.render_rgb(t.to_rgb()).rgb for k, t in (("network", network), ("refined", refined))}
        else:
            gt = sc.render_spectral(truth, WAVELENGTHS_NM).spectral
            imgs = {k: sc.render_spectral(t, WAVELENGTHS_NM).spectral
                    for k, t in (("network", network), ("refined", refined))}
        out[name] = {k: float(metrics.spectral_metrics(gt, v, geo.mask).psnr_mean) for k, v in imgs.items()}
    return out


def study_one(name: str, brdf, lighting, weights=None, novel_envs: Sequence[str] = (),
              novel: bool = True) -> dict[str, Any]:
    """One row: self-reproduction before/after refinement (+ novel-lighting PSNR if ``novel``)."""
    photo = photo_under(brdf, lighting)
    t0 = time.perf_counter()
    table = generate_brdf(photo * lighting.network_gain(), weights=weights)
    t_net = time.perf_counter() - t0
    res = refine_brdf(table, photo, lighting, RefineOptions(clip_level=None))
    row = {"material": name, "lighting": lighting.label,
           "self_psnr_network": res.before.psnr_db, "self_de_network": res.before.delta_e2000,
           "self_psnr_refined": res.after.psnr_db, "self_de_refined": res.after.delta_e2000,
           "seconds_network": t_net, "seconds_refine": res.seconds, "warnings": res.warnings}
    if novel:
        row["novel"] = _novel_scores(brdf, table, res.table, input_image._is_rgb_only(brdf), novel_envs)
    return row


def run_study(items: Sequence[tuple[str, Any]], lightings: Sequence, weights=None,
              novel_envs: Sequence[str] = (), progress: Callable[[float], None] | None = None,
              log: Callable[[str], None] = print, novel: bool = True) -> list[dict[str, Any]]:
    """Rows for every (material, lighting); novel lighting (if ``novel``) is scored for the first
    lighting only."""
    rows = []
    total = len(items) * len(lightings)
    for i, (name, brdf) in enumerate(items):
        for k, light in enumerate(lightings):
            row = study_one(name, brdf, light, weights, novel_envs, novel=novel and k == 0)
            rows.append(row)
            log(f"{name:<28} {light.label:<34} self {row['self_psnr_network']:6.2f} → "
                f"{row['self_psnr_refined']:6.2f} dB  ΔE {_f(row['self_de_network'])} → "
                f"{_f(row['self_de_refined'])}  ({row['seconds_refine']:.1f} s)")
            if progress is not None:
                progress(len(rows) / total)
    return rows


def _f(x) -> str:
    return "  n/a" if x is None else f"{x:5.2f}"


def study_items(limit: int | None = None, rgl_dir: Path | None = None) -> list[tuple[str, Any]]:
    """The held-out corpus test materials (first ``limit``) and the real RGL RGB files."""
    items: list[tuple[str, Any]] = [(m.name, m) for m in test_materials(limit)]
    if rgl_dir is not None and rgl_dir.is_dir():
        items += [(p.stem, load_brdf(p)) for p in sorted(rgl_dir.glob("*.bsdf"))]
    return items


def summarise(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per-lighting minima and means of self-reproduction, and novel-lighting means."""
    out: dict[str, Any] = {"by_lighting": {}, "novel": {}}
    for light in dict.fromkeys(r["lighting"] for r in rows):
        sel = [r for r in rows if r["lighting"] == light]
        de = [r["self_de_refined"] for r in sel if r["self_de_refined"] is not None]
        out["by_lighting"][light] = {
            "n": len(sel),
            "psnr_network_mean": float(np.mean([r["self_psnr_network"] for r in sel])),
            "psnr_refined_mean": float(np.mean([r["self_psnr_refined"] for r in sel])),
            "psnr_refined_min": float(np.min([r["self_psnr_refined"] for r in sel])),
            "de_refined_mean": float(np.mean(de)) if de else None,
            "de_refined_max": float(np.max(de)) if de else None,
            "seconds_refine_mean": float(np.mean([r["seconds_refine"] for r in sel]))}
    novel_rows = [r for r in rows if "novel" in r]
    for scene in dict.fromkeys(k for r in novel_rows for k in r["novel"]):
        vals = [r["novel"][scene] for r in novel_rows if scene in r["novel"]]
        out["novel"][scene] = {k: float(np.mean([v[k] for v in vals])) for k in ("network", "refined")}
    return out
