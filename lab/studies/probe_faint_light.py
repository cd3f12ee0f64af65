"""Why a refined table fails under other chrome-ball lights: knots seen only through faint light.

For one grey-ball photo of ``../shared/data/photos/psm_gray_chrome`` under the light unwrapped from
its chrome ball (as ``bench/photos_leave_one_out.py --modes chrome``), refine the network's table
with the given ``prior_floor`` values (:class:`specgen_addon.generate.refine.RefineOptions`) and
report: its self-reproduction, its prediction of the eleven other photos under their chrome-ball
lights (at the input's fitted power, as the bench) and under their file directions, the
Lambertian floor, the environment's share of the ball's light by view angle, and the table's
values at large θd (mean over φd and wavelength), where only the environment's light from the
sides and behind the ball reaches.

Usage: ``.venv/bin/python lab/studies/probe_faint_light.py --input 2 --prior-floors 1e-11 1e-6``
(notes: lab/notebook/real-photos-network.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))

import photos_leave_one_out as loo


def main(argv=None) -> int:
    from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf, render_under
    from specgen_addon.model.runtime.inference import generate_brdf
    from specgen_addon.photo.photo_lighting import parse_lighting
    from specgen_addon.photo.sphere_image import EXPOSURE, SphereCrop
    from specgen_addon.render import sphere_geometry

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--input", type=int, default=2)
    ap.add_argument("--prior-floors", type=float, nargs="+", default=[1e-11, 1e-6])
    ap.add_argument("--tmp", type=Path, default=Path("/tmp/specgen_probe_faint"))
    args = ap.parse_args(argv)
    args.tmp.mkdir(parents=True, exist_ok=True)
    i = args.input
    lights = loo.load_lights(loo.DATA / "lights.txt")
    crops = [loo.crop("gray", j) for j in range(12)]
    geo = sphere_geometry(loo.SIZE)
    masks = [geo.mask & (c.image.max(-1) < CLIP_LEVEL) & (c.image.max(-1) > 0) for c in crops]
    photo = crops[i].image.astype(np.float64)
    held = [j for j in range(12) if j != i]
    photos, hm = [crops[j].image for j in held], [masks[j] for j in held]
    lighting = loo.chrome_lighting(i, photo, None, args.tmp)
    power = lighting.lights[0].power
    held_chrome = {j: loo.chrome_lighting(j, None, power, args.tmp) for j in held}
    held_file = {j: loo.file_lighting(lights[j]) for j in held}
    print(f"gray.{i}: {lighting.label}")
    white = loo.white_render(lighting)
    ok = masks[i]
    albedo = (photo[ok] * white[ok]).sum(0) / (white[ok] ** 2).sum(0)
    print("  Lambertian floor, held-out chrome lights:",
          loo.score([loo.white_render(held_chrome[j]) * albedo for j in held], photos, hm))
    env_only = parse_lighting(lighting.env, exposure=lighting.exposure, calibrated=True, key_light=False)
    lamp_only = parse_lighting(None, lights=lighting.lights)
    start = generate_brdf(SphereCrop(photo * lighting.network_gain(), crops[i].copied))
    cos_v = geo.normals[..., 2]
    for floor in args.prior_floors:
        res = refine_brdf(start, photo, lighting, RefineOptions(clip_level=CLIP_LEVEL, exclude=crops[i].saturated,
                                                                 prior_floor=floor))
        tab = res.table
        print(f"  prior_floor {floor:g}: self-reproduction {res.after.psnr_db:.2f} dB")
        for name, held_light in (("chrome", held_chrome), ("file", held_file)):
            preds = [render_under(tab, held_light[j].scene(loo.SIZE), EXPOSURE) for j in held]
            print(f"    held-out photos under their {name} lights: {loo.score(preds, photos, hm)}")
        env_part = render_under(tab, env_only.scene(loo.SIZE), EXPOSURE).mean(-1)
        lamp_part = render_under(tab, lamp_only.scene(loo.SIZE), EXPOSURE).mean(-1)
        for lo, hi in ((0.0, 0.2), (0.2, 0.6), (0.6, 1.01)):
            s = geo.mask & (cos_v >= lo) & (cos_v < hi)
            print(f"    cos θv in [{lo}, {hi}): photo {photo.mean(-1)[s].mean():.3f}, lamp's part "
                  f"{lamp_part[s].mean():.3f}, environment's part {env_part[s].mean():.3f}")
        g = np.asarray(tab.values).mean(axis=(2, 3))
        print("    table, θh rows 0/30/60°, θd columns 0/30/60/85°:",
              np.array2string(g[[0, 30, 60]][:, [0, 30, 60, 85]], precision=3))
    return 0


if __name__ == "__main__":
    sys.exit(main())
