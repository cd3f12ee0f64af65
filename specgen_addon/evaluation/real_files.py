"""Scores on real RGL RGB files: the network alone, refined, and the MERL grid's own ceiling.

For one measured RGB file and one set of weights: the file's canonical input photo
(:func:`specgen_addon.train.real_rgb.canonical_photo`, as ``evaluate`` renders it), the network's
spectral table from it (and, with ``refine``, that table refined to the photo), each rendered on a
sphere and projected to linear sRGB, against the measured file rendered in RGB
(:func:`specgen_addon.render.render_rgb`), in every scene: the protocol's two distant lights and
the held-out maps (:data:`specgen_addon.render.environment_maps.HELDOUT_ENVS`). PSNR as everywhere in the project
(:func:`specgen_addon.render.metrics.spectral_metrics`, over the sphere, per channel, averaged).

The *ceiling* is the file's own table on the MERL grid (the best any predicted table can do) scored
the same way: what the representation itself costs on that material.

The measured renders and the photos are cached (:func:`specgen_addon.common.cache.cache_root`),
since every fold of a cross-validation scores the same files.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from specgen_addon.common.cache import cache_root
from specgen_addon.brdf.formats import load_brdf
from specgen_addon.evaluation.protocol import DISTANT_LIGHTS, WAVELENGTHS_NM
from specgen_addon.generate.refine import RefineOptions, refine_brdf
from specgen_addon.model.runtime.inference import generate_brdf
from specgen_addon.render import (environment_maps as lighting, metrics, render_rgb, render_spectral,
                                  sphere_geometry)


def scenes() -> list[tuple[str, dict[str, Any]]]:
    """(label, render keywords) of the scored scenes: ``distant`` and ``env-<map>`` per held-out map."""
    return [("distant", {"lights": DISTANT_LIGHTS})] + [
        (f"env-{e}", {"environment": lighting.load_environment(e)}) for e in lighting.HELDOUT_ENVS]


def _measured_render(path: Path, label: str, kw: dict[str, Any], resolution: int) -> np.ndarray:
    """The measured file's RGB render in one scene (cached by file, scene and resolution)."""
    cached = cache_root() / "real-files" / f"{path.stem}_{path.stat().st_size}_{label}_{resolution}.npy"
    if cached.is_file():
        return np.load(cached)
    rgb = np.asarray(render_rgb(load_brdf(path), sphere_geometry(resolution), **kw).rgb, dtype=np.float32)
    cached.parent.mkdir(parents=True, exist_ok=True)
    tmp = cached.with_name(cached.stem + ".tmp.npy")
    np.save(tmp, rgb)
    tmp.replace(cached)
    return rgb


def score_table(path: Path, table: Any, resolution: int = 64,
                scene_list: Sequence[tuple[str, dict[str, Any]]] | None = None) -> dict[str, float]:
    """``{"psnr_<scene>": dB}`` of a table (spectral or RGB) against the measured file ``path``."""
    geo = sphere_geometry(resolution)
    out = {}
    for label, kw in scene_list if scene_list is not None else scenes():
        gt = _measured_render(path, label, kw, resolution)
        if getattr(table, "is_spectral", False):
            pred = render_spectral(table, geo, wavelengths_nm=WAVELENGTHS_NM, **kw).rgb
        else:
            pred = render_rgb(table, geo, **kw).rgb
        out[f"psnr_{label}"] = float(metrics.spectral_metrics(gt, pred, geo.mask).psnr_mean)
    return out


def score_real_file(path: Path, weights: str | Path | None, resolution: int = 64, refine: bool = True,
                    scene_list: Sequence[tuple[str, dict[str, Any]]] | None = None) -> dict[str, Any]:
    """Network alone (``psnr_<scene>``) and, with ``refine``, refined (``psnr_refined_<scene>``) on
    one real file, from its canonical input photo."""
    from specgen_addon.train.real_rgb import canonical_photo

    path = Path(path)
    scene_list = scenes() if scene_list is None else scene_list
    photo = canonical_photo(path, cache_root() / "train-data", log=lambda _m: None)
    t0 = time.perf_counter()
    table = generate_brdf(photo, weights=weights, wavelengths_nm=WAVELENGTHS_NM)
    row: dict[str, Any] = {"material": path.stem, **score_table(path, table, resolution, scene_list)}
    if refine:
        fit = refine_brdf(table, photo, options=RefineOptions(clip_level=None))
        row |= {f"psnr_refined_{k[5:]}": v for k, v in score_table(path, fit.table, resolution, scene_list).items()}
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def table_ceiling(path: Path, resolution: int = 64,
                  scene_list: Sequence[tuple[str, dict[str, Any]]] | None = None) -> dict[str, Any]:
    """The file's own MERL-grid table (as training tabulates it) scored against the measurement."""
    from specgen_addon.train.data import load_file_materials

    table = load_file_materials([Path(path)], cache_root() / "train-data")[0].brdf
    return {"material": Path(path).stem,
            **{f"ceiling_{k[5:]}": v for k, v in score_table(Path(path), table, resolution, scene_list).items()}}


def summarise(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean, minimum and the file at the minimum of every ``psnr_*`` / ``ceiling_*`` column
    present in all rows."""
    keys = [k for k in rows[0] if k.startswith(("psnr_", "ceiling_")) and all(k in r for r in rows)] if rows else []
    out: dict[str, Any] = {"n": len(rows)}
    for k in keys:
        vals = np.array([r[k] for r in rows])
        out[k] = {"mean": float(vals.mean()), "min": float(vals.min()),
                  "min_file": rows[int(vals.argmin())]["material"]}
    return out
