"""``paper-tables`` end to end: train ablation arms, fill every table cell, draw plots, write the report.

The cache lives beside the report (``<out dir>/.cache/paper-tables/<settings key>/``, gitignored), so a
rerun with the same settings only computes what is missing; ``fresh`` discards it.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.evaluation import ablation as abl
from specgen_addon.evaluation import baselines, plots, protocol, tables
from specgen_addon.common.cache import read_json, write_json
from specgen_addon.evaluation.report_text import compose
from specgen_addon.model import DEFAULT_WEIGHTS
from specgen_addon.spectral import spectra

#: Full configuration (docs/results.md) and the CI smoke configuration.
FULL = {"resolution": 128, "n_materials": 10, "env_sampling_scale": 1.0, "lut_size": None, "band_count": 20}
SMOKE = {"resolution": 64, "n_materials": 2, "env_sampling_scale": 0.25, "lut_size": 5, "band_count": 5}
#: Real RGL RGB files checked in the real-data table (../shared/data/rgl beside the repo).
REAL_RGL_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgl"
REAL_ROLES = ("env_unseen1", "distant")


def _key(d: dict) -> str:
    return hashlib.sha1(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:10]


def _file_key(path: Path | None) -> str:
    if path is None or not Path(path).is_file():
        return "none"
    h = hashlib.sha1()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:10]


def machine_description() -> str:
    """E.g. ``2-core x86_64, 24 GB, CPU only``."""
    mem = ""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                mem = f", {round(int(line.split()[1]) / 1024 ** 2)} GB"
    except OSError:
        pass
    return f"{os.cpu_count()}-core {platform.machine()}{mem}, CPU only"


def git_commit() -> str:
    try:
        res = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parents[2], timeout=10)
        return res.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _parse_materials(spec: str | None, default: int) -> tuple[int | None, list[str] | None]:
    if spec is None:
        return default, None
    spec = spec.strip()
    if spec.isdigit():
        if int(spec) < 1:
            raise SpecGenError("--materials needs at least one material")
        return int(spec), None
    return None, [s.strip() for s in spec.split(",") if s.strip()]


def run_paper_tables(out: Path, img_dir: Path | None = None, smoke: bool = False,
                     materials: str | None = None, budget_minutes: float | None = None,
                     ablation_steps: int | None = None, ablation: bool = True,
                     weights: Path | None = None, resolution: int | None = None, fresh: bool = False,
                     progress: bool = True, prepare: bool = False, report_only: bool = False,
                     photo_only: bool = False, input_photo: str = "independent") -> Path:
    """Run the whole evaluation and write the markdown report ``out`` (returns its path).

    ``prepare`` computes only what does not need the shipped weights (ground-truth renders,
    baseline cells, the ablation arms), filling the cache for a later full run; no report then.
    ``report_only`` computes nothing: it rebuilds the report and figures from the cache (the arms
    recorded there by the last full run), e.g. after editing the discussion file.
    ``photo_only`` runs only the photo-only protocol (table (f): the photo fits, their uplifted
    renders and SpecGen in the same scenes) and writes a report of that part alone.
    ``input_photo`` is the sphere photo SpecGen and the photo fits see (:data:`.tables.INPUT_PHOTOS`).
    """
    t_start = time.perf_counter()
    out = Path(out)
    if not out.parent.is_dir():
        raise SpecGenError(f"{out}: output directory {out.parent} does not exist")
    img_dir = Path(img_dir) if img_dir is not None else out.parent / "img"
    conf = dict(SMOKE if smoke else FULL)
    if resolution is not None:
        conf["resolution"] = int(resolution)
    n_mat, names = _parse_materials(materials, conf["n_materials"])

    weights_path = Path(weights) if weights is not None else DEFAULT_WEIGHTS
    if not weights_path.is_file() and not prepare:
        raise SpecGenError(f"{weights_path}: SpecGen weights not found (train them or pass --weights)")
    settings = tables.Settings(resolution=conf["resolution"], n_materials=n_mat or 0, material_names=names,
                               env_sampling_scale=conf["env_sampling_scale"], lut_size=conf["lut_size"],
                               band_count=conf["band_count"], smoke=smoke, input_photo=input_photo)
    root = out.parent / ".cache" / "paper-tables"
    cache = root / f"{'smoke' if smoke else 'full'}-{_key(settings.describe())}"
    if report_only and (fresh or not (cache.is_dir() and any(p.name != "settings.json" for p in cache.iterdir()))):
        raise SpecGenError(f"--report-only: nothing is cached for these settings in {cache} "
                           "(run paper-tables without --report-only first)")
    if fresh:
        tables.clear_cache(cache)
    cache.mkdir(parents=True, exist_ok=True)
    write_json(cache / "settings.json", settings.describe())
    log = (lambda msg: print(msg, file=sys.stderr)) if progress else (lambda msg: None)
    log(f"paper-tables: cache {cache}")

    mats = protocol.test_materials(n_mat, names)
    h = tables.Harness(settings, cache, log=log)
    h.figure_names = h.figure_material_names(mats)
    specgen_arm = f"{tables.SPECGEN}@{_file_key(weights_path)}"

    # 1. Ablation arms (equal step budgets, deterministic seeds), trained or loaded from the cache.
    arms: dict[str, abl.ArmResult] = {}
    abl_settings = None
    if report_only and not photo_only:
        abl_settings, arms = abl.load_arms(cache / "arms.json")
    elif ablation and not photo_only:
        abl_settings = abl.ablation_settings(smoke=smoke, steps=ablation_steps, budget_minutes=budget_minutes,
                                             cache_dir=root / "ablation", log=log)
        arms = abl.train_arms(abl_settings, root / "ablation", progress=progress, log=log)
        abl.save_arms(cache / "arms.json", abl_settings, arms)

    # 2. Cells: baselines (photo-only and oracle) and SpecGen in every scene, ablation arms under
    # distant light.
    jobs: list[tuple[str, Any, Any]] = []
    for m in ([] if report_only else mats):
        jobs.append(("photo", m, None))
        if not photo_only:
            jobs.append(("baselines", m, None))
        if not prepare:
            jobs.append((specgen_arm, m, weights_path))
            jobs.append((tables.refined_arm(specgen_arm), m, weights_path))
            if not photo_only:
                jobs.append(("robustness", m, weights_path))
        for name, arm in arms.items():
            jobs.append((arm.key, m, arm.weights))
    bar = _bar(len(jobs), "paper-tables", progress)
    for kind, m, w in jobs:
        bar.set_postfix_str(f"{m.name}: {kind.split('@')[0]}")
        if kind == "photo":
            h.run_photo_baselines(m, tables.MAIN_ROLES)
        elif kind == "baselines":
            h.run_baselines(m, tables.BASELINE_ROLES)
        elif kind == specgen_arm:
            h.run_model(kind, w, m, tables.MAIN_ROLES, keep_images=True)
        elif kind == tables.refined_arm(specgen_arm):
            h.run_model(kind, w, m, tables.MAIN_ROLES, refine=True)
        elif kind == "robustness":
            for role in tables.ROLES_B:
                env = h.scenes[role].env
                h.run_model(tables.robustness_arm(specgen_arm, env), w, m, [role], input_env=env)
                h.run_model(tables.robustness_arm(specgen_arm, env, lighting_given=True), w, m, [role],
                            input_env=env, lighting_given=True)
        else:
            h.run_model(kind, w, m, tables.ROLES_ABLATION, direct=True)
        bar.update(1)
    bar.close()
    if prepare:
        record_run(cache, "prepare", time.perf_counter() - t_start)
        log(f"paper-tables: prepared the weight-independent cells ({time.perf_counter() - t_start:.0f} s)")
        return out

    # 3. Real data: the RGL RGB files, SpecGen projected to RGB vs the measured BRDF.
    real: dict[str, dict[str, dict]] = {}
    real_note = ""
    if photo_only:
        real_note = "(not run: --photo-only)"
    elif REAL_RGL_DIR.is_dir():
        files = sorted(p for p in REAL_RGL_DIR.glob("*_rgb.bsdf"))
        for path in files:
            real[path.stem] = ({r: h.cell(f"real-{specgen_arm}", path.stem, r) for r in REAL_ROLES}
                               if report_only else h.run_real(path.stem, path, weights_path, REAL_ROLES, specgen_arm))
    else:
        real_note = f"(skipped: {REAL_RGL_DIR} not found)"

    # 3b. Per corpus family, network alone.
    families = None if photo_only else (read_json(cache / "families" / f"{specgen_arm}.json") if report_only
                                        else h.run_families(weights_path, specgen_arm,
                                                            REAL_RGL_DIR if REAL_RGL_DIR.is_dir() else None))

    # 4. Figures and report.
    figures = {} if photo_only else make_figures(h, mats, specgen_arm, img_dir)
    runs = (read_json(cache / "runs.json") or []) if report_only else \
        record_run(cache, "photo-only" if photo_only else "full", time.perf_counter() - t_start)
    text = build_report(h, mats, specgen_arm, weights_path, arms, abl_settings, real, real_note,
                        figures, out, smoke, runs, photo_only, families)
    with atomic_write(out, overwrite=True) as tmp:
        tmp.write_text(text, encoding="utf-8")
    log(f"paper-tables: wrote {out} ({time.perf_counter() - t_start:.0f} s)")
    return out


class _NoBar:
    def set_postfix_str(self, s: str) -> None: ...
    def update(self, n: int) -> None: ...
    def close(self) -> None: ...


def _bar(total: int, desc: str, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="job", file=sys.stderr, dynamic_ncols=True)


# -- figures --------------------------------------------------------------------------------------

def make_figures(h: tables.Harness, mats: Sequence[Any], specgen_arm: str, img_dir: Path) -> dict[str, Path]:
    """The three PNGs; returns their paths by role."""
    wl = h.wl
    methods = [specgen_arm] + list(h.s.baselines)
    names = [m.name for m in mats]
    panels = {}
    for role in ("env_unseen1", "distant", "shape_env"):
        curves = {}
        for method in methods:
            cells = [h.cell(method, n, role) for n in names]
            cells = [c for c in cells if c is not None]
            if cells:
                key = tables.SPECGEN if method == specgen_arm else method
                curves[key] = (wl, np.mean([c["psnr"] for c in cells], axis=0))
        panels[f"{h.scenes[role].shape}, {h.scenes[role].lighting_label}"] = curves
    out = {"psnr": plots.plot_psnr_per_wavelength(panels, {tables.SPECGEN: "SpecGen", **baselines.LABELS},
                                                   img_dir / "psnr_per_wavelength.png")}
    rows, curves_fig = [], None
    for name in h.figure_names:
        gt = h.ground_truth(next(m for m in mats if m.name == name), tables.FIGURE_ROLE)
        pred_path = h.image_path(name, tables.FIGURE_ROLE, specgen_arm)
        if not pred_path.is_file():
            continue
        with np.load(pred_path) as d:
            pred = d["spectral"]
        rows.append((name, gt.spectral, pred, gt.mask))
        if curves_fig is None:
            by_method = {"gt": gt.spectral, tables.SPECGEN: pred}
            for b in h.s.baselines:
                p = h.image_path(name, tables.FIGURE_ROLE, b)
                if p.is_file():
                    with np.load(p) as d:
                        by_method[b] = d["spectral"]

            preview = spectra.srgb_encode(np.clip(gt.rgb / max(np.percentile(gt.rgb[gt.mask], 99), 1e-9), 0, 1))
            curves_fig = plots.plot_spectral_curves(
                f"{name}, {h.scenes[tables.FIGURE_ROLE].lighting_label}", by_method,
                figure_pixels(gt.mask), wl, {"gt": "ground truth", tables.SPECGEN: "SpecGen", **baselines.LABELS},
                img_dir / "spectral_curves.png", preview=preview)
    if rows:
        out["grid"] = plots.plot_wavelength_grid(rows, wl, protocol.FIGURE_WAVELENGTHS_NM,
                                                 img_dir / "gt_vs_specgen_wavelengths.png")
    if curves_fig is not None:
        out["curves"] = curves_fig
    return out


def figure_pixels(mask: np.ndarray) -> list[tuple[int, int]]:
    """Three pixels of the sphere: centre, upper-left rim region, lower-right region."""
    hgt, wid = mask.shape
    cands = [(hgt // 2, wid // 2), (int(hgt * 0.3), int(wid * 0.3)), (int(hgt * 0.72), int(wid * 0.68))]
    return [p for p in cands if mask[p]] or [tuple(np.argwhere(mask)[0])]


# -- report ---------------------------------------------------------------------------------------

def build_report(h: tables.Harness, mats: Sequence[Any], specgen_arm: str, weights: Path,
                 arms: dict[str, "abl.ArmResult"], abl_settings: Any, real: dict, real_note: str,
                 figures: dict[str, Path], out: Path, smoke: bool, runs: list[dict],
                 photo_only: bool = False, families: dict | None = None) -> str:
    """The markdown of docs/results.md (or of the photo-only part alone)."""
    return compose(h, mats, specgen_arm, weights, arms, abl_settings, real, real_note, figures, out,
                   smoke, runs, machine_description(), git_commit(), photo_only, families)


def record_run(cache: Path, mode: str, seconds: float) -> list[dict]:
    """Append this run's wall time to ``<cache>/runs.json``; returns every run recorded there."""
    runs = read_json(cache / "runs.json") or []
    runs.append({"mode": mode, "seconds": round(float(seconds), 1), "commit": git_commit(),
                 "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())})
    write_json(cache / "runs.json", runs)
    return runs
