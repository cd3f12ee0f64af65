"""Leave-one-light-out on real photos: one grey-ball photo in, the other eleven predicted.

Data: ../shared/data/photos/psm_gray_chrome (12 photos of a matte grey ball and 12 of a chrome ball
under the same 12 distant lights; 8-bit values that behave as linear). For each input photo and each
way of knowing its light:

* ``file``: the dataset's light direction (lights.txt), power 1;
* ``chrome``: unwrapped from the chrome ball under the same light (:mod:`specgen_addon.photo.light_probe`:
  environment + the clipped highlight as a distant light, its power fitted to the input photo);
* ``estimated``: nothing given, distant lights + ambient estimated from the input ball's shading
  (:mod:`specgen_addon.photo.light_estimate`); the held-out photos are predicted under the file's
  lights, as for ``file`` (so the estimate is judged by the table it leads to);
* ``canonical``: nothing given, the default canonical studio (how a user who gives no light runs);

the network's table and the refined table are rendered under each held-out photo's light (the same
kind of light: file directions for ``file`` and ``canonical``, the held-out chrome ball for
``chrome``) and compared with the held-out photos: PSNR after one exposure factor shared by all
eleven (least squares), and the chromaticity error (angle between mean RGB vectors, degrees). A
Lambertian fitted to the same input photo under the same light is the floor. As the product does,
under a given light the network alone is shown the photo refitted and re-rendered in the canonical
studio (:mod:`specgen_addon.generate.canonical_input`), and the refinement starts from the table of
the photo × ``network_gain``; ``--network-input photo`` shows the network alone that too (the way
before 2026-12-07). The self-reproduction of the network is that of the network alone.

    .venv/bin/python bench/photos_leave_one_out.py --inputs 0 3 6 9 \\
        --json docs/photos_leave_one_out.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

DATA = REPO.parent / "shared" / "data" / "photos" / "psm_gray_chrome"
SIZE = 128


def load_lights(path: Path) -> np.ndarray:
    return np.loadtxt(path, skiprows=1)


def crop(kind: str, i: int):
    """The photo's canonical crop about its mask's circle (the same circle for every photo)."""
    from specgen_addon.photo.sphere_image import PhotoSource

    return PhotoSource(DATA / kind / f"{kind}.{i}.tga", encoding="linear",
                       mask=DATA / kind / f"{kind}.mask.tga").crop(SIZE)


def file_lighting(direction: np.ndarray):
    from specgen_addon.photo.photo_lighting import Light, parse_lighting

    return parse_lighting(None, lights=(Light(tuple(direction)),))


def chrome_lighting(i: int, photo: np.ndarray | None, power: float | None, tmp: Path):
    """The lighting of chrome photo ``i``; its highlight's power fitted to ``photo`` (the input) or
    set to ``power`` (a held-out photo: the input's power, so nothing is fitted to what is predicted)."""
    from specgen_addon.photo.light_probe import probe_lighting, read_probe
    from specgen_addon.photo.photo_lighting import Light, parse_lighting

    probe = read_probe(DATA / "chrome" / f"chrome.{i}.tga", mask=DATA / "chrome" / "chrome.mask.tga",
                       encoding="linear")
    lighting = probe_lighting(probe, tmp / f"probe{i}.exr", photo, overwrite=True)
    if power is not None and lighting.lights:
        lighting = parse_lighting(lighting.env, exposure=lighting.exposure, calibrated=True, key_light=False,
                                  lights=tuple(Light(li.direction, power) for li in lighting.lights))
    return lighting


def white_render(lighting) -> np.ndarray:
    """Photo (S, S, 3) of a white Lambertian ball under ``lighting`` (exact irradiance / π)."""
    from specgen_addon.photo.sphere_image import EXPOSURE, _key_light
    from specgen_addon.render import sphere_geometry

    geo = sphere_geometry(SIZE)
    n = geo.normals[geo.mask]
    env = lighting.environment()
    rgb = env.irradiance_rgb(n) / np.pi if env is not None else np.zeros((n.shape[0], 3))
    keys = ([_key_light()] if lighting.key_light or lighting.is_canonical else []) + \
        [li.distant_light() for li in lighting.lights]
    for key in keys:
        rgb = rgb + np.maximum(n @ key.unit_direction(), 0.0)[:, None] * key.rgb()[None] / np.pi
    out = np.zeros((SIZE, SIZE, 3))
    out[geo.mask] = rgb * EXPOSURE
    return out


def lambertian_albedo(photo: np.ndarray, mask: np.ndarray, lighting) -> np.ndarray:
    """(3,) per-channel albedo of the Lambertian fitted to ``photo``'s ``mask`` pixels under
    ``lighting`` (least squares against :func:`white_render`): the floor's material."""
    white = white_render(lighting)
    return (photo[mask] * white[mask]).sum(0) / np.maximum((white[mask] ** 2).sum(0), 1e-30)


def score(preds: list[np.ndarray], photos: list[np.ndarray], masks: list[np.ndarray]) -> dict:
    """PSNR (dB, mean over channels, peak = the held-out photos' 99.9th percentile) after one
    exposure factor shared by all, and the mean chromaticity angle (degrees)."""
    p = np.concatenate([q[m] for q, m in zip(preds, masks)])
    y = np.concatenate([q[m] for q, m in zip(photos, masks)])
    k = float((p * y).sum() / max((p * p).sum(), 1e-30))
    peak = float(np.percentile(y, 99.9))
    mse = np.mean((k * p - y) ** 2, axis=0) / peak ** 2
    psnr = float(np.mean([-10 * math.log10(max(m, 1e-30)) for m in mse]))
    angles = []
    for q, ph, m in zip(preds, photos, masks):
        a, b = q[m].mean(0), ph[m].mean(0)
        cos = float(a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-30))
        angles.append(math.degrees(math.acos(min(1.0, max(-1.0, cos)))))
    return {"psnr_db": round(psnr, 2), "chroma_deg": round(float(np.mean(angles)), 2), "exposure": round(k, 4)}


def run(inputs: list[int], modes: list[str], tmp: Path, network_input: str = "canonical",
        estimate_ambient: str | None = None, refine: bool = True, every_band: bool = False) -> dict:
    from specgen_addon.generate.canonical_input import network_crop
    from specgen_addon.generate.pipeline import NETWORK_BAND_GAP_NM, network_reproduction
    from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf, render_under
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.photo_lighting import InputLighting
    from specgen_addon.photo.sphere_image import EXPOSURE, SphereCrop
    from specgen_addon.render import sphere_geometry

    gap = None if every_band else NETWORK_BAND_GAP_NM      # as Generate: every band, or 40 nm apart
    lights = load_lights(DATA / "lights.txt")
    crops = [crop("gray", j) for j in range(12)]
    inside = sphere_geometry(SIZE).mask
    masks = [inside & (c.image.max(-1) < CLIP_LEVEL) & (c.image.max(-1) > 0) for c in crops]
    rows = []
    for i in inputs:
        photo = crops[i].image.astype(np.float64)
        for mode in modes:
            t0 = time.perf_counter()
            if mode == "file":
                lighting = file_lighting(lights[i])
            elif mode == "chrome":
                lighting = chrome_lighting(i, photo, None, tmp)
            elif mode == "estimated":
                from specgen_addon.photo.light_estimate import estimate_lights

                lighting = estimate_lights(photo, crops[i].saturated, ambient_from=estimate_ambient).lighting()
            else:
                lighting = InputLighting()
            power = lighting.lights[0].power if mode == "chrome" and lighting.lights else None
            held = [j for j in range(12) if j != i]
            if mode == "chrome":
                held_light = {j: chrome_lighting(j, None, power, tmp) for j in held}
            else:
                held_light = {j: file_lighting(lights[j]) for j in held}
            # as the product: the refinement starts from the photo's own table; the network alone
            # (no refinement) is shown the photo re-rendered in the studio (generate.canonical_input)
            refit = network_input == "canonical" and not lighting.is_canonical
            start = generate_brdf(SphereCrop(photo * lighting.network_gain(), crops[i].copied),
                                  band_gap_nm=gap) if refine or not refit else None
            t1 = time.perf_counter()
            table, input_seconds = start, 0.0
            if refit:
                table = generate_brdf(network_crop(crops[i], photo, lighting, CLIP_LEVEL)[0], band_gap_nm=gap)
                input_seconds = time.perf_counter() - t1
            res = refine_brdf(start, photo, lighting, RefineOptions(clip_level=CLIP_LEVEL,
                                                                     exclude=crops[i].saturated)) if refine else None
            alone = network_reproduction(table, photo, lighting, CLIP_LEVEL, crops[i].saturated)
            albedo = lambertian_albedo(photo, masks[i], lighting)
            photos = [crops[j].image for j in held]
            hm = [masks[j] for j in held]
            out = {"input": i, "mode": mode, "lighting": lighting.label,
                   "self_reproduction_network_db": round(alone.psnr_db, 2),
                   "self_reproduction_refined_db": round(res.after.psnr_db, 2) if res else None}
            for name, tab in (("network", table), ("refined", res.table if res else None)):
                if tab is None:
                    continue
                preds = [render_under(tab, held_light[j].scene(SIZE), EXPOSURE) for j in held]
                out[name] = score(preds, photos, hm)
            out["lambertian"] = score([white_render(held_light[j]) * albedo for j in held], photos, hm)
            out["network_input_seconds"] = round(input_seconds, 2)   # fit + re-render + the network
            out["seconds"] = round(time.perf_counter() - t0, 1)
            print(json.dumps(out), flush=True)
            rows.append(out)
    summary = {}
    for mode in modes:
        sel = [r for r in rows if r["mode"] == mode]
        summary[mode] = {k: round(float(np.mean([r[k]["psnr_db"] for r in sel])), 2)
                         for k in ("network", "refined", "lambertian") if all(k in r for r in sel)}
    return {"rows": rows, "mean_psnr_db": summary}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--inputs", type=int, nargs="+", default=list(range(12)))
    ap.add_argument("--modes", nargs="+", default=["file", "chrome", "estimated", "canonical"],
                    choices=["file", "chrome", "estimated", "canonical"])
    ap.add_argument("--network-input", choices=["canonical", "photo"], default="canonical",
                    help="under a given light, the network sees the photo re-rendered in the canonical "
                         "studio (the product's way, default) or the photo × network_gain (before 2026-12-07)")
    ap.add_argument("--estimate-ambient", choices=["fit", "unlit"], default=None,
                    help="where the estimated light's ambient comes from (default: the product's, "
                         "specgen_addon.photo.light_estimate.AMBIENT_FROM)")
    ap.add_argument("--network-only", action="store_true",
                    help="score the network alone and the Lambertian floor; skip the refinement (quick)")
    ap.add_argument("--every-band", action="store_true",
                    help="the network evaluates every band (default: as Generate, bands 40 nm apart "
                         "and the others interpolated)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--tmp", type=Path, default=Path("/tmp/specgen_photos_loo"))
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"needs the shared photos at {DATA}", file=sys.stderr)
        return 2
    args.tmp.mkdir(parents=True, exist_ok=True)
    res = run(args.inputs, args.modes, args.tmp, args.network_input, args.estimate_ambient,
              refine=not args.network_only, every_band=args.every_band)
    print(json.dumps(res["mean_psnr_db"], indent=1))
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
