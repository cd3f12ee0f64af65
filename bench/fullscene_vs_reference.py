"""Check: the Full Scene render of generated materials against the reference renderer and Exact.

Usage::

    python bench/fullscene_vs_reference.py TABLE.npz [...]          # given tables
    python bench/fullscene_vs_reference.py --check --cache DIR      # the whole check (below)

``--check`` generates (network + refinement, as Generate does) from: the example photo
``examples/sphere.png``; the canonical input photo of one held-out test material of every corpus
family; the canonical input photo of every real RGL file in ``../shared/data/rgl`` (if present).
Tables are kept in ``--cache`` and reused.

Per table: bake it (default tolerance), put it on a sphere lit by one D65 sun (the same sphere,
camera and sun as ``bench/bake_vs_reference.py``), render it with the Full Scene job
(``ops.render_fullscene``) as shipped (exact direct light, closures for the bounces) and with the
closure stack alone, and with the Exact mode; print per renderer the mean CIEDE2000 of the sRGB
projections and the energy ratio (sum of all bands over the sphere) against the reference
renderer (``specgen_addon.render``), plus the closure fit's rendered error under the three check
lights (``specgen_addon.bake.closure_fit.fit_check``) that the panel shows, and Cycles' closure stack against the
same fitted model rendered by the reference renderer (how exactly Cycles draws the fit).
"""

from __future__ import annotations

import argparse
import runpy
import tempfile
import time
from importlib import import_module
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]
SUN = (0.35, 0.45, 0.82)
#: The check's target for the Full Scene render against the reference renderer.
MAX_DELTA_E, MAX_ENERGY_OFF = 1.0, 0.03
RGL_DIR = REPO.parent / "shared" / "data" / "rgl"


def check_tables(cache: Path) -> list[tuple[str, Path]]:
    """(name, table path) of the whole check, generating the missing tables into ``cache``."""
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.generate import pipeline
    from specgen_addon.corpus.generate import material_family
    from specgen_addon.brdf.formats import load_brdf
    from specgen_addon.evaluation.trained_network import mixed_test_materials

    cache.mkdir(parents=True, exist_ok=True)
    sources: list[tuple[str, object]] = [("example sphere.png", REPO / "examples" / "sphere.png")]
    sources += [(f"{material_family(m)} ({m.name})", m) for m in mixed_test_materials(1)]
    sources += [(f"RGL {p.stem}", p) for p in sorted(RGL_DIR.glob("*.bsdf"))]
    out = []
    for name, src in sources:
        path = cache / (name.split(" (")[0].replace(" ", "_").replace(".", "_") + ".npz")
        if not path.exists():
            t = time.perf_counter()
            photo = src if isinstance(src, Path) and src.suffix == ".png" else input_image.render_input(
                load_brdf(src) if isinstance(src, Path) else src)
            pipeline.generate(photo).table.save(path)
            print(f"generated {name} in {time.perf_counter() - t:.0f} s", flush=True)
        out.append((name, path))
    return out


def sphere_scene(render, scene_mod, info, res: int, samples: int):
    """A new scene: the ortho camera, the sphere with the baked material, one D65 sun."""
    sc, _ = scene_mod.new_reference_sphere_scene(lambda: render.make_material("check", info), SUN)
    sc.render.resolution_x = sc.render.resolution_y = res
    sc.cycles.samples, sc.cycles.use_denoising = samples, False
    return sc


def body_energy(ref: np.ndarray, got: np.ndarray) -> float:
    """Energy ratio without the brightest 1 % of the reference's pixels: a near-mirror highlight
    one or two pixels wide can hold most of the energy, and how a renderer samples inside those
    pixels then decides the plain ratio."""
    total = ref.sum(-1)
    mask = total > 0
    body = mask & (total < np.percentile(total[mask], 99))
    return float(got[body].sum() / ref[body].sum())


def compare(ref: np.ndarray, got: np.ndarray, wl: np.ndarray) -> tuple[float, float]:
    """(mean ΔE2000 of the sRGB projections, energy ratio) over the reference's covered pixels."""
    from specgen_addon.render.photo_reproduction import delta_e2000, photo_scale
    from specgen_addon.render.spectral_exr import linear_srgb_preview

    mask = ref.sum(-1) > 0
    a, b = linear_srgb_preview(ref, wl)[mask], linear_srgb_preview(got, wl)[mask]
    return float(delta_e2000(a, b, photo_scale(a))), float(got[mask].sum() / ref[mask].sum())


def target_missed(delta_e: float, energy: float) -> str:
    """Why a Full Scene result misses the check's target ("" if it meets it)."""
    why = []
    if delta_e > MAX_DELTA_E:
        why.append(f"colour: ΔE2000 {delta_e:.2f} > {MAX_DELTA_E}")
    if abs(energy - 1.0) > MAX_ENERGY_OFF:
        why.append(f"energy: {energy:.3f}, off by more than {100 * MAX_ENERGY_OFF:.0f} %")
    return "; ".join(why)


def where_by_half_angle(ref: np.ndarray, got: np.ndarray, geo) -> str:
    """Where a render's energy differs from the reference's on the sphere: per band of the half
    angle θh (degrees) of each pixel's (sun, view) pair, the reference's share of the energy and
    the ratio got/reference there (a lookup error shows as one band off, e.g. θh near 0 or 90°)."""
    from specgen_addon.brdf.rusinkiewicz import half_diff_from_io
    from specgen_addon.render.geometry import shading_frame, to_local

    mask = geo.mask
    n = geo.normals[mask]
    t, b = shading_frame(n)
    sun = np.asarray(SUN) / np.linalg.norm(SUN)
    wi = to_local(np.broadcast_to(sun, n.shape), t, b, n)
    wo = to_local(np.broadcast_to(np.asarray(geo.view_dir, np.float64), n.shape), t, b, n)
    theta_h = np.degrees(half_diff_from_io(wi, wo)[0])
    r, g = ref[mask].sum(-1), got[mask].sum(-1)
    cells = []
    for lo, hi in zip((0, 1, 2, 4, 8, 15, 30, 60, 80), (1, 2, 4, 8, 15, 30, 60, 80, 90)):
        sel = (theta_h >= lo) & (theta_h < hi) & ((r > 0) | (g > 0))
        if sel.any() and r.sum() > 0:
            ratio = f"{g[sel].sum() / r[sel].sum():.3f}" if r[sel].sum() > 0 else "inf"
            cells.append(f"θh {lo}–{hi}°: {100 * r[sel].sum() / r.sum():.1f} % of the energy, ×{ratio}")
    return "; ".join(cells)


def before_after(named: list[tuple[str, Path]], res: int) -> None:
    """The closure fit with every table entry weighed alike (``weighting="entries"``, the fit of
    earlier versions, and its reported residual) against the fit a bake now keeps
    (``check=True``), both rendered by the reference renderer against the table. No Blender."""
    from specgen_addon.bake.closure_fit import fit_closures
    from specgen_addon.bake.closure_fit.fit_check import FitBRDF
    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry
    from specgen_addon.brdf.table import BRDFTable

    print("| material | before: reported fit error | before: ΔE2000 | before: energy | after: ΔE2000 "
          "| after: energy | after: worst of 3 lights |")
    print("|---|---|---|---|---|---|---|")
    for name, path in named:
        table = BRDFTable.load(path)
        wl = table.wavelengths
        light = [DistantLight(SUN, np.pi)]
        ref = render_spectral(table, sphere_geometry(res), lights=light, wavelengths_nm=wl).spectral
        old, new = fit_closures(table, weighting="entries"), fit_closures(table, check=True)
        cells = [f"{100 * old.max_error:.1f} %"]
        for fit in (old, new):
            got = render_spectral(FitBRDF(fit), sphere_geometry(res), lights=light, wavelengths_nm=wl).spectral
            cells += [f"{x:.3f}" if i else f"{x:.2f}" for i, x in enumerate(compare(ref, got, wl))]
        print(f"| {name} | " + " | ".join(cells + [f"{new.rendered_error:.2f}"]) + " |", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", nargs="*", type=Path)
    ap.add_argument("--check", action="store_true", help="the example, one per family, the RGL files")
    ap.add_argument("--cache", type=Path, default=Path("fullscene_check_tables"))
    ap.add_argument("--resolution", type=int, default=96)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--only", default="", help="check only the materials whose name contains this")
    ap.add_argument("--where", action="store_true",
                    help="also print where on the sphere (by half angle θh) Exact's energy differs")
    ap.add_argument("--before-after", action="store_true",
                    help="only the closure fit's two weightings against the table (no Blender)")
    args = ap.parse_args()
    named = [(p.stem, p) for p in args.tables] + (check_tables(args.cache) if args.check else [])
    named = [(n, p) for n, p in named if args.only.lower() in n.lower()]
    if not named:
        ap.error("give tables or --check")
    if args.before_after:
        before_after(named, args.resolution)
        return 0

    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry
    from specgen_addon.bake.closure_fit.fit_check import FitBRDF, rendered_fit_error
    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry
    from specgen_addon.brdf.table import BRDFTable

    pkg = batch.load_package()
    bake = import_module("specgen_addon.bake.lookup")
    render = import_module(f"{pkg.__name__}.ops.render")
    fullscene = import_module(f"{pkg.__name__}.ops.render_fullscene")
    scene_mod = import_module(f"{pkg.__name__}.ops.scene")
    print(describe_machine())
    print(f"sphere {args.resolution}² px, one D65 sun from {SUN}, Full Scene {args.samples} samples")
    print("| material | closure fit ΔE2000 (3 lights) | Full Scene ΔE2000 | energy | target met "
          "| closures alone ΔE2000 | energy | Exact ΔE2000 | energy | Full Scene vs Exact ΔE2000 "
          "| Cycles closures vs NumPy fit ΔE2000 | Full Scene energy without the top 1 % pixels |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    missed = []
    quiet = lambda *_: None  # noqa: E731
    res = args.resolution
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in named:
            table = BRDFTable.load(path)
            wl = table.wavelengths
            ref = render_spectral(table, sphere_geometry(res), lights=[DistantLight(SUN, np.pi)],
                                  wavelengths_nm=wl).spectral
            info = bake.bake_atlas(table, Path(tmp) / f"{path.stem}.exr")
            fit_de = rendered_fit_error(info.closures, table)
            fit_ref = render_spectral(FitBRDF(info.closures), sphere_geometry(res),
                                      lights=[DistantLight(SUN, np.pi)], wavelengths_nm=wl).spectral
            got = {}
            for label, exact in (("full", True), ("closures", False)):
                sc = sphere_scene(render, scene_mod, info, res, args.samples)
                got[label] = fullscene.FullSceneRenderJob(sc, None, wl, exact_direct=exact, warn=quiet,
                                                          log=quiet, preview_png=False).run()
            sc = sphere_scene(render, scene_mod, info, res, args.samples)
            got["exact"] = render.SpectralRenderJob(sc, None, samples=2, resolution=(res, res),
                                                    warn=quiet).run()
            cells = [f"{fit_de:.2f}"]
            for label in ("full", "closures", "exact"):
                de, energy = compare(ref, got[label], wl)
                cells += [f"{de:.2f}", f"{energy:.3f}"]
                if label == "full":
                    why = target_missed(de, energy)
                    cells.append(f"**no** ({why})" if why else "yes")
                    if why:
                        missed.append(f"{name} ({why})")
            cells.append(f"{compare(got['exact'], got['full'], wl)[0]:.2f}")
            cells.append(f"{compare(fit_ref, got['closures'], wl)[0]:.2f}")
            cells.append(f"{body_energy(ref, got['full']):.3f}")
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
            if args.where:
                print(f"  {name}, Exact vs reference: "
                      + where_by_half_angle(ref, got["exact"], sphere_geometry(res)), flush=True)
    print(f"target (Full Scene vs reference: ΔE2000 ≤ {MAX_DELTA_E}, energy within "
          f"{100 * MAX_ENERGY_OFF:.0f} %): met by {len(named) - len(missed)} of {len(named)}"
          + ("" if not missed else "; missed: " + "; ".join(missed)))
    return 1 if missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
