"""Benchmark of the reference renderer: speed, and how much the environment sampling moves PSNR.

Prints markdown tables for docs/dev/renderer.md:

1. seconds to render a 256² sphere at the default 21 bands under an environment map (corpus
   materials; "cold" includes preparing the scene's samples, "warm" reuses a prepared Scene);
2. seconds per canonical 128² input image (what training renders thousands of);
3. doubling the environment samples: PSNR of ground truth vs a perturbed "prediction" rendered with
   S and 2S directions per pixel (same seed), and each render's own PSNR against an 8S reference.

Usage::

    python bench/render_reference.py [--materials 6] [--resolution 256] [--study-resolution 128]
                                     [--figure docs/img/contact_sheet.png]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py, beside this script


from specgen_addon.photo import sphere_image as input_image  # noqa: E402
from specgen_addon.render import environment_maps as lighting  # noqa: E402
from specgen_addon.render import metrics  # noqa: E402
from specgen_addon.spectral import spectra  # noqa: E402
from specgen_addon.corpus import Reflectance, generate_corpus  # noqa: E402
from specgen_addon.render import EnvSampling, Scene, sphere_geometry  # noqa: E402

WL = spectra.DEFAULT_WAVELENGTHS_NM


def perturbed(m):
    """A plausible 'prediction': roughness ×1.3 and diffuse spectrum ×0.9."""
    diffuse = None if m.diffuse is None else Reflectance(
        m.diffuse.source, tuple(float(v) * 0.9 for v in m.diffuse.values))
    return dataclasses.replace(m, alpha=float(min(m.alpha * 1.3, 1.0)), diffuse=diffuse)


def pick_materials(count: int):
    corpus = generate_corpus(200, 0)
    test = [m for m in corpus if m.split == "test"]
    chosen, kinds = [], set()
    for m in test:  # one of each kind first, then the rest in corpus order
        if m.kind.split(":")[0] not in kinds:
            kinds.add(m.kind.split(":")[0])
            chosen.append(m)
    chosen += [m for m in test if m not in chosen]
    return chosen[:count]


def sheet_materials(count: int):
    """A varied handful: plastics of distinct spectra (glossy to rough), a coated one, gold, silver."""
    corpus = generate_corpus(200, 0)
    wanted = [lambda m: m.kind == "metal:Au", lambda m: m.kind == "metal:Ag",
              lambda m: m.kind == "plastic+coat"]
    chosen = [next(m for m in corpus if w(m)) for w in wanted]
    sources = set()
    for m in sorted((m for m in corpus if m.kind == "plastic"), key=lambda m: m.alpha):
        if len(chosen) >= count:
            break
        if m.diffuse.source not in sources and (not sources or m.alpha > 0.2):
            sources.add(m.diffuse.source)
            chosen.append(m)
    return chosen[:count]


def timing(materials, resolution: int) -> None:
    env = lighting.load_environment("studio")
    print(f"\n### {resolution}² sphere, {WL.size} bands, `studio` environment, "
          f"{EnvSampling().total} directions/pixel\n")
    print("Wall seconds (CPU seconds of this process in brackets).\n")
    print("| material | kind | cold s (prepare + render) | warm s (prepared Scene) |")
    print("| --- | --- | ---: | ---: |")
    cold_all, warm_all = [], []
    env.irradiance_rgb(np.array([[0.0, 0.0, 1.0]]))  # per-map table, built once per process
    for m in materials[:3]:
        t0, c0 = time.perf_counter(), time.process_time()
        scene = Scene(sphere_geometry(resolution), environment=env)
        scene.render_spectral(m, WL)
        cold = (time.perf_counter() - t0, time.process_time() - c0)
        warm = []
        for _ in range(2):
            t0, c0 = time.perf_counter(), time.process_time()
            scene.render_spectral(m, WL)
            warm.append((time.perf_counter() - t0, time.process_time() - c0))
        warm = min(warm)
        cold_all.append(cold)
        warm_all.append(warm)
        print(f"| {m.name} | {m.kind} | {cold[0]:.2f} ({cold[1]:.2f}) | {warm[0]:.2f} ({warm[1]:.2f}) |")
    c, w = np.mean(cold_all, axis=0), np.mean(warm_all, axis=0)
    print(f"| **mean** | | **{c[0]:.2f}** ({c[1]:.2f}) | **{w[0]:.2f}** ({w[1]:.2f}) |")

    print(f"\n### Canonical {input_image.CANONICAL_SIZE}² input image (RGB from 21 bands, "
          f"{input_image.input_sampling().total} directions/pixel + key light)\n")
    input_image._scene.cache_clear()
    t0 = time.perf_counter()
    input_image.render_input(materials[0])
    first = time.perf_counter() - t0
    per, cpu = [], []
    for m in materials:
        t0, c0 = time.perf_counter(), time.process_time()
        input_image.render_input(m)
        per.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    print(f"first image (prepares the scene): {first:.2f} s; then {np.mean(per):.2f} s per image "
          f"(mean of {len(per)}, min {np.min(per):.2f}, max {np.max(per):.2f}; CPU "
          f"{np.mean(cpu):.2f} s)")


def doubling(materials, resolution: int, envs: list[str]) -> None:
    base = EnvSampling()
    print(f"\n### Doubling the environment samples ({resolution}², {WL.size} bands, "
          f"S = {base.total} directions/pixel)\n")
    print("PSNR (dB, `specgen_addon.render.metrics`) of GT vs prediction (roughness ×1.3, diffuse ×0.9), "
          "and each GT render's own PSNR against an 8S reference.\n")
    print("| env | material | kind | GT vs pred, S | 2S | Δ | 8S | GT(S) vs 8S | GT(2S) vs 8S |")
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    deltas = []
    geo = sphere_geometry(resolution)
    for name in envs:
        env = lighting.load_environment(name)
        scenes = {f: Scene(geo, environment=env, sampling=base.scaled(f)) for f in (1, 2, 8)}
        for m in materials:
            p = perturbed(m)
            gt = {f: s.render_spectral(m, WL).spectral for f, s in scenes.items()}
            pr = {f: s.render_spectral(p, WL).spectral for f, s in scenes.items()}
            cmp = {f: metrics.spectral_metrics(gt[f], pr[f], geo.mask).psnr_mean for f in gt}
            self_s = metrics.spectral_metrics(gt[8], gt[1], geo.mask).psnr_mean
            self_2s = metrics.spectral_metrics(gt[8], gt[2], geo.mask).psnr_mean
            d = cmp[2] - cmp[1]
            deltas.append(d)
            print(f"| {name} | {m.name} | {m.kind} | {cmp[1]:.2f} | {cmp[2]:.2f} | {d:+.2f} | "
                  f"{cmp[8]:.2f} | {self_s:.1f} | {self_2s:.1f} |", flush=True)
    a = np.abs(deltas)
    print(f"\n|Δ| over {len(a)} cases: mean {a.mean():.2f} dB, max {a.max():.2f} dB")


def contact_sheet(materials, path: Path, resolution: int = 128) -> None:
    """Spheres in RGB (canonical-style lighting) and at three wavelengths (grey, common scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from specgen_addon.render import DistantLight

    bands = np.array([450.0, 550.0, 650.0])
    env = lighting.load_environment(input_image.CANONICAL_ENV)
    scene = Scene(sphere_geometry(resolution), [DistantLight(input_image.KEY_LIGHT_DIRECTION,
                                                             input_image.KEY_LIGHT_IRRADIANCE)], env)
    fig, axes = plt.subplots(len(materials), 4, figsize=(4 * 1.6, len(materials) * 1.6))
    for r, m in enumerate(materials):
        rgb = np.clip(input_image.EXPOSURE * scene.render_spectral(m, WL).rgb, 0, 1)
        spec = scene.render_spectral(m, bands).spectral * input_image.EXPOSURE
        panels = [spectra.srgb_encode(rgb)] + [spectra.srgb_encode(np.clip(spec[..., k], 0, 1))
                                              for k in range(3)]
        for c, img in enumerate(panels):
            ax = axes[r, c]
            ax.imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            ax.set_xticks([]), ax.set_yticks([])
            if r == 0:
                ax.set_title("RGB" if c == 0 else f"{bands[c - 1]:.0f} nm", fontsize=9)
            if c == 0:
                ax.set_ylabel(f"{m.name}\n{m.kind}", fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"\nwrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", type=int, default=6, help="corpus test materials in the study")
    ap.add_argument("--resolution", type=int, default=256, help="timing resolution (default 256)")
    ap.add_argument("--study-resolution", type=int, default=128, help="doubling-study resolution")
    ap.add_argument("--envs", default="studio,courtyard,sunset", help="maps of the doubling study")
    ap.add_argument("--skip-study", action="store_true", help="timings only")
    ap.add_argument("--figure", type=Path, help="also draw the contact sheet (PNG)")
    args = ap.parse_args()
    print(f"machine: {describe_machine()}")
    print(f"command: python bench/render_reference.py {' '.join(sys.argv[1:])}")
    materials = pick_materials(args.materials)
    timing(materials, args.resolution)
    if not args.skip_study:
        doubling(materials, args.study_resolution, args.envs.split(","))
    if args.figure:
        contact_sheet(sheet_materials(5), args.figure)


if __name__ == "__main__":
    main()
