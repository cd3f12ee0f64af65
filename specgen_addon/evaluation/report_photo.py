"""The photo-only protocol's part of the report.

Every method gets what a real user has: the one input photo (:meth:`.tables.Harness.input_photo`) and its
known lighting. SpecGen generates its BRDF from it; each photo-only baseline fits an analytic RGB
BRDF to it (:mod:`.photo_fit`) and uplifts the fitted colours with one colour-science method. All
are rendered in the evaluation scenes by the same renderer and scored against the ground truth.

Adding a SpecGen variant (e.g. the refined table) is one entry in :func:`specgen_variants`: its
cells are those :meth:`.tables.Harness.run_model` writes under its arm name, its self-reproduction
the :data:`.tables.SELF_ROLE` cell of :meth:`.tables.Harness.run_self_reproduction`.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from specgen_addon.evaluation import baselines, protocol, report, tables

#: Required margin (dB) of SpecGen over every photo-only baseline.
TARGET_MARGIN_DB = 2.0


def specgen_variants(specgen_arm: str) -> list[tuple[str, str]]:
    """``(arm, label)`` of the SpecGen rows of the photo-only tables and targets, in row order."""
    return [(specgen_arm, "**SpecGen** (network alone)"),
            (tables.refined_arm(specgen_arm), "**SpecGen, refined to the photo**")]


def photo_rows(methods: Sequence[str]) -> list[tuple[str, str]]:
    """``(arm, label)`` of the photo-only baselines."""
    return [(tables.photo_arm(m), f"{baselines.LABELS[m]} (photo fit)") for m in methods]


def self_reproduction_column(get: report.CellGetter, materials: Sequence[str]) -> report.Column:
    """``RGB PSNR / ΔE2000`` of the arm's :data:`.tables.SELF_ROLE` cells, mean over materials."""
    def value(arm: str) -> str:
        cells = [get(arm, m, tables.SELF_ROLE) for m in materials]
        cells = [c for c in cells if c is not None]
        if not cells:
            return "—"
        psnr = float(np.mean([c["rgb_psnr"] for c in cells]))
        des = [c["delta_e2000"] for c in cells if c.get("delta_e2000") is not None]
        de = f"{np.mean(des):.2f}" if des else "—"
        return f"{psnr:.2f} dB / {de}" + (f" (n={len(cells)})" if len(cells) < len(materials) else "")

    return report.Column("Self-reproduction RGB PSNR / ΔE2000", value)


#: The photo-only tables: (title, scene roles).
TABLES = (("sphere", tables.ROLES_A), ("shape transfer", tables.ROLES_E))


def target_rows(get: report.CellGetter, materials: Sequence[str], specgen_arm: str,
                methods: Sequence[str]) -> list[tuple[str, float | None, float, str]]:
    """Targets-table rows: each SpecGen variant against the *best* photo-only baseline, per table
    (the smallest mean PSNR difference over the baselines)."""
    out = []
    for title, roles in TABLES:
        for arm, label in specgen_variants(specgen_arm):
            gaps = [report.psnr_gap(get, materials, roles, arm, tables.photo_arm(m)) for m in methods]
            gaps = [g for g in gaps if g is not None]
            out.append((f"Photo-only, {title}: {label.replace('*', '')} beats every photo-only baseline by "
                        f"≥ {TARGET_MARGIN_DB:g} dB", min(gaps) if len(gaps) == len(methods) else None,
                        TARGET_MARGIN_DB, f"≥ +{TARGET_MARGIN_DB:g} dB"))
    return out


def fits_table(fits: dict[str, dict | None]) -> str:
    """One row per material: the fitted analytic BRDF and its residual."""
    def tri(v: Sequence[float]) -> str:
        return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"

    rows = []
    for name, fit in fits.items():
        if fit is None:
            rows.append([name] + ["—"] * 6)
            continue
        b = fit["brdf"]
        coat = f"{b['coat']:.3f} @ {b['coat_alpha']:.3f}" if b.get("coat_alpha") else "—"
        rows.append([name, f"{b['alpha']:.3f}", tri(b["diffuse"]), tri(b["f0"]), f"{b['edge']:.2f}", coat,
                     f"{100 * fit['residual']:.1f} %"])
    return report.md_table(["Material", "α", "diffuse (linear sRGB)", "F0 (linear sRGB)", "edge",
                            "coat weight @ α_c", "residual (rel. RMS)"], rows, "lrrrrrr")


def section(h: "tables.Harness", mats: Sequence[Any], specgen_arm: str, add: Callable[[str], None],
            heading: Callable[[str], None], lighting: Callable[[Any], str]) -> None:
    """Append the photo-only section (tables (f)) to a report via ``add`` / ``heading``."""
    names = [m.name for m in mats]
    get = h.cell
    methods = list(h.s.photo_baselines)
    rows = specgen_variants(specgen_arm) + photo_rows(methods)
    heading("## (f) Photo-only protocol: every method sees only the input photo")
    add("")
    add("The fair counterpart of tables (a) and (e): a baseline gets what a real user "
        "has, the same single sphere photo SpecGen gets (see *Protocol*) and its known "
        "lighting. It fits an analytic RGB BRDF to the photo (`specgen_addon/evaluation/photo_fit.py`: "
        "diffuse colour, specular F0 colour, GGX roughness, white Schlick grazing term, clear coat "
        "with its own roughness; per roughness pair the colours are a non-negative least-squares "
        "problem over basis renders under the input scene, the best pair on a grid is refined by "
        "golden-section search), uplifts the fitted diffuse and F0 colours to reflectance spectra "
        "with each colour-science method (each colour uplifted exactly, PBRT's `RGBAlbedoSpectrum` "
        "convention), and the resulting spectral analytic BRDF is rendered in the evaluation scenes "
        "exactly as SpecGen's. Mean over the test materials; **bold** = best of the column. "
        "*Self-reproduction*: the method's spectral BRDF rendered under the input's own lighting "
        "against the input image (RGB PSNR with the photo's 99.9th percentile as peak; mean "
        "CIEDE2000; over the sphere without its one-pixel grazing rim, θo > 81°, which the fit also "
        "leaves out, as the refinement does).")
    add("")
    extra = [self_reproduction_column(get, names)]
    for title, roles in TABLES:
        labels = {r: lighting(h.scenes[r]) for r in roles}
        add(f"**{title.capitalize()}**:")
        add("")
        add(report.rows_table(get, names, labels, rows, extra))
        add("")
    add("Per material (sphere, then shape transfer):")
    add("")
    arm_labels = dict(rows)
    arms = [a for a, _ in rows]
    for _, roles in TABLES:
        add(report.methods_table(get, names, {r: lighting(h.scenes[r]) for r in roles}, arms, arm_labels))
        add("")
    add("By the source of the material's spectrum (mean over both tables' scenes). Some corpus diffuse "
        "spectra are drawn from Otsu 2018's PCA model, the space the Otsu 2018 uplifting reconstructs in:")
    add("")
    groups: dict[str, list[str]] = {}
    for m in mats:
        groups.setdefault(protocol.spectrum_source(m), []).append(m.name)
    add(report.group_table(get, groups, [r for _, roles in TABLES for r in roles], arms, arm_labels))
    add("")
    add("The fitted analytic BRDFs (the same fit feeds every uplifting method):")
    add("")
    add(fits_table({n: h.cell_fit(n) for n in names}))
    add("")
