"""One round of alternating the estimated light and the refined table, on the shared grey-ball photos.

The light is estimated as the product does (``--input-env estimate``), the network's table refined
under it; then the light is fitted again with the refined table's own response in place of the
Lambertian (each candidate distant light rendered through the table, the ambient through the table's
directional albedo), searched on rings about the first estimate; the table is refined again under
the new light and both tables predict the other eleven photos under the file's lights, scored as
``bench/photos_leave_one_out.py`` does. It answers whether the light moves when the material is no
longer assumed Lambertian, and whether a second round helps.

    .venv/bin/python lab/studies/joint_light_round.py 1 2 10 5
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))

import photos_leave_one_out as bench

from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf, render_under
from specgen_addon.model.runtime.inference import generate_brdf
from specgen_addon.photo.light_estimate import ASSUMED_ALBEDO, estimate_lights
from specgen_addon.photo.light_probe import _nnls, ball_normals
from specgen_addon.photo.photo_lighting import Light, parse_lighting
from specgen_addon.photo.sphere_image import EXPOSURE, SphereCrop
from specgen_addon.render import sphere_geometry

LUM = np.array([0.2126, 0.7152, 0.0722])
STEP = 2          # every other pixel of the crop


def frames(nn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.cross(nn, [0.0, 1.0, 0.0])
    bad = np.linalg.norm(t, axis=1) < 1e-6
    t[bad] = np.cross(nn[bad], [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(nn, t)


def response(table, nn, t, b, d: np.ndarray) -> np.ndarray:
    """Luminance of each pixel under a distant light from ``d`` through the table, × π (a white
    Lambertian gives cos θi)."""
    wi = np.stack([t @ d, b @ d, nn @ d], -1)
    wo = np.stack([t[:, 2], b[:, 2], nn[:, 2]], -1)
    f = table.eval_rgb(wi, wo) @ LUM
    return math.pi * f * np.maximum(nn @ d, 0.0)


def albedo(table, nn, t, b, samples: int = 128) -> np.ndarray:
    """Directional albedo of the table towards the camera per pixel (a white Lambertian gives 1)."""
    rng = np.random.default_rng(0)
    u = rng.random((samples, 2))
    r, ph = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
    local = np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(1 - u[:, 0])], -1)   # cosine-weighted
    wo = np.stack([t[:, 2], b[:, 2], nn[:, 2]], -1)
    out = np.zeros(nn.shape[0])
    for w in local:
        out += table.eval_rgb(np.broadcast_to(w, wo.shape), wo) @ LUM
    return math.pi * out / samples


def refit(table, photo, first) -> tuple[np.ndarray, float, float, float]:
    """(direction, power, ambient, residual dB) of one light + ambient fitted with ``table``'s response,
    searched on rings of 8° to 1° about ``first``."""
    n, inside = ball_normals(photo.shape[0])
    lum = photo @ LUM
    use = inside & (lum > 0)
    use[1::STEP, :] = False
    use[:, 1::STEP] = False
    nn, y = n[use], lum[use]
    t, b = frames(nn)
    amb = albedo(table, nn, t, b)

    def fit(d):
        a = np.stack([amb, response(table, nn, t, b, d)], -1)
        c = _nnls(a, y, iterations=30)
        return c, float(np.sqrt(np.mean((a @ c - y) ** 2)))

    best = np.asarray(first, float)
    c, r = fit(best)
    for step in (8.0, 4.0, 2.0, 1.0):
        u = np.cross(best, [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(best, u)
        moved = True
        while moved:
            moved = False
            for a in np.linspace(0, 2 * math.pi, 8, endpoint=False):
                s = math.radians(step)
                cand = best * math.cos(s) + (u * math.cos(a) + v * math.sin(a)) * math.sin(s)
                cc, rr = fit(cand / np.linalg.norm(cand))
                if rr < r:
                    best, c, r, moved = cand / np.linalg.norm(cand), cc, rr, True
    scale = 1.0 / (EXPOSURE * ASSUMED_ALBEDO)
    peak = float(np.percentile(y, 99.9))
    return best, float(c[1] / EXPOSURE), float(c[0] * scale), 20 * math.log10(peak / r)


def main(inputs: list[int]) -> None:
    lights = bench.load_lights(bench.DATA / "lights.txt")
    crops = [bench.crop("gray", j) for j in range(12)]
    inside = sphere_geometry(bench.SIZE).mask
    masks = [inside & (c.image.max(-1) < CLIP_LEVEL) & (c.image.max(-1) > 0) for c in crops]
    scenes = {j: bench.file_lighting(lights[j]).scene(bench.SIZE) for j in range(12)}
    for i in inputs:
        photo = crops[i].image.astype(np.float64)
        held = [j for j in range(12) if j != i]

        def predict(table, held=held):
            preds = [render_under(table, scenes[j], EXPOSURE) for j in held]
            return bench.score(preds, [crops[j].image for j in held], [masks[j] for j in held])["psnr_db"]

        e = estimate_lights(photo, crops[i].saturated)
        light0 = e.lighting()
        start = generate_brdf(SphereCrop(photo * light0.network_gain(), crops[i].copied))
        opts = RefineOptions(clip_level=CLIP_LEVEL, exclude=crops[i].saturated)
        r0 = refine_brdf(start, photo, light0, opts)
        t0 = time.process_time()
        d1, p1, a1, res1 = refit(r0.table, photo, np.asarray(e.directions[0]))
        refit_cpu = time.process_time() - t0
        light1 = parse_lighting(None, lights=(Light(tuple(d1), p1),), ambient=a1)
        r1 = refine_brdf(start, photo, light1, opts)
        print(json.dumps({
            "input": i, "round0": {"ambient": round(e.ambient, 4), "angle_to_file_deg": round(
                math.degrees(math.acos(min(1, float(np.dot(e.directions[0], lights[i]))))), 1),
                "self_db": round(r0.after.psnr_db, 2), "refined_db": predict(r0.table)},
            "round1": {"moved_deg": round(math.degrees(math.acos(min(1, float(d1 @ e.directions[0])))), 2),
                       "ambient": round(a1, 4), "angle_to_file_deg": round(
                           math.degrees(math.acos(min(1, float(d1 @ lights[i])))), 1),
                       "light_residual_db": round(res1, 1), "self_db": round(r1.after.psnr_db, 2),
                       "refined_db": predict(r1.table), "refit_cpu_s": round(refit_cpu, 1)}}), flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1, 2, 10, 5])
