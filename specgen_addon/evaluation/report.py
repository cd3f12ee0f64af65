"""Markdown tables of the evaluation: cells ``{psnr_mean, ssim_mean, ...}`` → GitHub tables.

Pure functions of the cached cells (no rendering), so the report is rebuilt from a cache alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

Cell = Mapping[str, float] | None
#: ``get(arm, material, role) -> cell or None``.
CellGetter = Callable[[str, str, str], Cell]


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str | None = None) -> str:
    """A GitHub markdown table; ``align`` is one of ``l``/``r``/``c`` per column (default: l, then r)."""
    align = align or ("l" + "r" * (len(header) - 1))
    marks = {"l": ":--", "r": "--:", "c": ":-:"}
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(marks[a] for a in align) + " |"]
    for row in rows:
        if len(row) != len(header):
            raise ValueError(f"row has {len(row)} cells, header {len(header)}")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def fmt(cell: Cell, bold: bool = False) -> str:
    """``PSNR / SSIM`` of a cell (``—`` when missing), optionally bold."""
    if cell is None:
        return "—"
    s = f"{cell['psnr_mean']:.2f} / {cell['ssim_mean']:.4f}"
    return f"**{s}**" if bold else s


def mean_cell(cells: Sequence[Cell]) -> Cell:
    """Mean PSNR and SSIM over the present cells (None when none is present)."""
    present = [c for c in cells if c is not None]
    if not present:
        return None
    return {"psnr_mean": float(np.mean([c["psnr_mean"] for c in present])),
            "ssim_mean": float(np.mean([c["ssim_mean"] for c in present])), "n": len(present)}


def _row(cells: Sequence[Cell]) -> list[str]:
    psnrs = [c["psnr_mean"] if c is not None else -np.inf for c in cells]
    best = int(np.argmax(psnrs)) if any(np.isfinite(psnrs)) else -1
    return [fmt(c, bold=(i == best and len(cells) > 1)) for i, c in enumerate(cells)]


def methods_table(get: CellGetter, materials: Sequence[str], roles: Mapping[str, str],
                  methods: Sequence[str], labels: Mapping[str, str]) -> str:
    """Rows = material × lighting, columns = methods; then averages per lighting and overall.

    ``roles`` maps a scene role to its row label. Bold: the best PSNR of the row.
    """
    header = ["Material", "Lighting"] + [f"{labels.get(m, m)} PSNR / SSIM" for m in methods]
    rows = []
    for role, label in roles.items():
        for mat in materials:
            rows.append([mat, label] + _row([get(m, mat, role) for m in methods]))
    for role, label in roles.items():
        rows.append(["**Average**", label] + _row([mean_cell([get(m, mat, role) for mat in materials])
                                                   for m in methods]))
    if len(roles) > 1:
        rows.append(["**Average**", "all"] + _row([mean_cell([get(m, mat, r) for mat in materials
                                                              for r in roles]) for m in methods]))
    return md_table(header, rows, "ll" + "r" * len(methods))


def robustness_table(get: CellGetter, materials: Sequence[str], roles: Mapping[str, str],
                     methods: Sequence[str], labels: Mapping[str, str]) -> str:
    """Rows = environment maps, columns = methods (mean over materials)."""
    header = ["Environment map"] + [f"{labels.get(m, m)} PSNR / SSIM" for m in methods]
    rows = [[label] + _row([mean_cell([get(m, mat, role) for mat in materials]) for m in methods])
            for role, label in roles.items()]
    rows.append(["**Average**"] + _row([mean_cell([get(m, mat, r) for mat in materials for r in roles])
                                        for m in methods]))
    return md_table(header, rows)


def group_table(get: CellGetter, groups: Mapping[str, Sequence[str]], roles: Sequence[str],
                methods: Sequence[str], labels: Mapping[str, str]) -> str:
    """Rows = material groups (label → materials), columns = methods; mean over group × ``roles``."""
    header = ["Materials", "n"] + [f"{labels.get(m, m)} PSNR / SSIM" for m in methods]
    rows = [[label, str(len(mats))] + _row([mean_cell([get(m, mat, r) for mat in mats for r in roles])
                                            for m in methods])
            for label, mats in groups.items() if mats]
    return md_table(header, rows, "lr" + "r" * len(methods))


def per_material_table(get: CellGetter, materials: Sequence[str], arm: str, roles: Mapping[str, str]) -> str:
    """Rows = materials, columns = scene roles, for one arm."""
    header = ["Material"] + [f"{label} PSNR / SSIM" for label in roles.values()]
    rows = [[mat] + [fmt(get(arm, mat, r)) for r in roles] for mat in materials]
    rows.append(["**Average**"] + [fmt(mean_cell([get(arm, mat, r) for mat in materials])) for r in roles])
    return md_table(header, rows)


def arms_table(get: CellGetter, materials: Sequence[str], role: str, arms: Sequence[str],
               labels: Mapping[str, str]) -> str:
    """Rows = materials, columns = training arms, in one scene role; bold = best of the row."""
    header = ["Material"] + [f"{labels.get(a, a)} PSNR / SSIM" for a in arms]
    rows = [[mat] + _row([get(a, mat, role) for a in arms]) for mat in materials]
    rows.append(["**Average**"] + _row([mean_cell([get(a, mat, role) for mat in materials]) for a in arms]))
    return md_table(header, rows)


def grid_table(get: CellGetter, materials: Sequence[str], role: str,
               grid: Mapping[str, Mapping[str, str]], col_labels: Sequence[str]) -> str:
    """Rows = row label, columns = col label; ``grid[row][col] = arm`` (mean over materials)."""
    header = ["Fusion"] + [f"{c} PSNR / SSIM" for c in col_labels]
    rows = []
    for row_label, arms in grid.items():
        rows.append([row_label] + [fmt(mean_cell([get(arms[c], mat, role) for mat in materials]))
                                   if c in arms else "—" for c in col_labels])
    return md_table(header, rows)


def psnr_gap(get: CellGetter, materials: Sequence[str], roles: Sequence[str], arm: str, other: str) -> float | None:
    """Mean over materials × roles of PSNR(arm) − PSNR(other), on the cells both have."""
    diffs = []
    for mat in materials:
        for r in roles:
            a, b = get(arm, mat, r), get(other, mat, r)
            if a is not None and b is not None:
                diffs.append(a["psnr_mean"] - b["psnr_mean"])
    return float(np.mean(diffs)) if diffs else None


def targets_table(rows: Sequence[tuple[str, float | None, float, str]]) -> str:
    """Rows ``(target, measured gap in dB, required gap in dB, comparison)`` → met / missed."""
    out = []
    for name, measured, required, how in rows:
        if measured is None:
            out.append([name, "—", how, "not measured"])
            continue
        met = measured >= required if how.startswith("≥") else measured > required
        out.append([name, f"{measured:+.2f} dB", how, "met" if met else "**missed**"])
    return md_table(["Target", "Measured (mean PSNR difference)", "Required", "Result"], out, "lrll")


@dataclass(frozen=True)
class Column:
    """An extra column of :func:`rows_table`: ``value(arm) -> text`` (e.g. self-reproduction)."""

    header: str
    value: Callable[[str], str]


def rows_table(get: CellGetter, materials: Sequence[str], roles: Mapping[str, str],
               rows: Sequence[tuple[str, str]], extra: Sequence[Column] = ()) -> str:
    """Rows = methods ``(arm, label)``, columns = scene roles (mean over materials), their average,
    then ``extra`` columns. Bold: the best PSNR of each scene column."""
    cols = [[mean_cell([get(arm, mat, r) for mat in materials]) for r in roles] for arm, _ in rows]
    for i, (arm, _) in enumerate(rows):
        cols[i].append(mean_cell([get(arm, mat, r) for mat in materials for r in roles]))
    by_col = [_row([cols[i][j] for i in range(len(rows))]) for j in range(len(roles) + 1)]
    header = (["Method"] + [f"{label} PSNR / SSIM" for label in roles.values()] + ["Average PSNR / SSIM"]
              + [c.header for c in extra])
    body = [[label] + [by_col[j][i] for j in range(len(roles) + 1)] + [c.value(arm) for c in extra]
            for i, (arm, label) in enumerate(rows)]
    return md_table(header, body, "l" + "r" * (len(header) - 1))
