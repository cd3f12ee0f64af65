"""Figures of the evaluation (matplotlib, Agg backend, PNG).

* :func:`plot_psnr_per_wavelength`: mean PSNR per band for each method (one panel per scene);
* :func:`plot_wavelength_grid`: ground truth vs SpecGen at seven wavelengths for a few materials
  (the paper's Fig. 4 layout);
* :func:`plot_spectral_curves`: the radiance spectrum at a few pixels: GT, SpecGen and baselines.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from specgen_addon.common.atomic_io import atomic_write

#: One colour per method, stable across figures.
METHOD_STYLE = {
    "gt": ("k", "-"), "specgen": ("tab:red", "-"), "mallett2019": ("tab:blue", "--"),
    "smits1999": ("tab:orange", "--"), "otsu2018": ("tab:green", "--"), "jakob2019": ("tab:purple", "--"),
}

#: Magnification of the error row of :func:`plot_wavelength_grid`.
ERROR_GAIN = 4


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, overwrite=True) as tmp:
        fig.savefig(tmp, format="png")
    _plt().close(fig)
    return path


def plot_psnr_per_wavelength(panels: Mapping[str, Mapping[str, tuple[Sequence[float], Sequence[float]]]],
                             labels: Mapping[str, str], path: str | Path) -> Path:
    """``panels[title][method] = (wavelengths_nm, mean PSNR per band in dB)``, one axis per panel."""
    plt = _plt()
    n = len(panels)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 3.8), dpi=110, squeeze=False)
    for ax, (title, curves) in zip(axes[0], panels.items()):
        for method, (wl, psnr) in curves.items():
            colour, style = METHOD_STYLE.get(method, (None, "-"))
            ax.plot(wl, psnr, style, color=colour, marker="o", ms=3, lw=1.4, label=labels.get(method, method))
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("wavelength (nm)")
        ax.set_ylabel("PSNR (dB)")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def _band_index(wavelengths_nm: np.ndarray, wl: float) -> int:
    return int(np.argmin(np.abs(np.asarray(wavelengths_nm) - wl)))


def plot_wavelength_grid(rows: Sequence[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
                         wavelengths_nm: np.ndarray, show_nm: Sequence[float], path: str | Path) -> Path:
    """GT and prediction at ``show_nm`` for each ``(label, gt, pred, mask)`` (images H×W×Λ).

    Each band of a material is shown with one grey scale (its GT maximum) so GT and prediction are
    comparable; a third row shows |pred − GT| magnified ``ERROR_GAIN`` times on the same scale.
    """
    plt = _plt()
    k = len(show_nm)
    fig, axes = plt.subplots(3 * len(rows), k, figsize=(1.5 * k, 1.6 * 3 * len(rows)), dpi=110,
                             squeeze=False)
    for r, (label, gt, pred, mask) in enumerate(rows):
        for c, wl in enumerate(show_nm):
            b = _band_index(wavelengths_nm, wl)
            vmax = max(float(gt[..., b][mask].max()) if mask.any() else 1.0, 1e-12)
            for j, (img, name) in enumerate(((gt[..., b], "GT"), (pred[..., b], "SpecGen"),
                                             (ERROR_GAIN * np.abs(pred[..., b] - gt[..., b]), f"|error| ×{ERROR_GAIN}"))):
                ax = axes[3 * r + j][c]
                ax.imshow(np.where(mask, img, 0.0), cmap="gray", vmin=0.0, vmax=vmax)
                ax.set_xticks([])
                ax.set_yticks([])
                if r == 0 and j == 0:
                    ax.set_title(f"{wavelengths_nm[b]:.0f} nm", fontsize=9)
                if c == 0:
                    ax.set_ylabel(f"{label}\n{name}", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_spectral_curves(label: str, spectra_by_method: Mapping[str, np.ndarray], pixels: Sequence[tuple[int, int]],
                         wavelengths_nm: np.ndarray, labels: Mapping[str, str], path: str | Path,
                         preview: np.ndarray | None = None) -> Path:
    """Radiance spectra at ``pixels`` (row, col) of each method's image (H×W×Λ); GT under ``"gt"``.

    ``preview`` (H×W×3 sRGB in [0, 1]) is drawn first with the pixels marked.
    """
    plt = _plt()
    extra = 1 if preview is not None else 0
    n = len(pixels) + extra
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.4), dpi=110, squeeze=False)
    if preview is not None:
        ax = axes[0][0]
        ax.imshow(np.clip(preview, 0, 1))
        for i, (r, c) in enumerate(pixels):
            ax.plot(c, r, "o", mfc="none", mec="yellow", ms=8)
            ax.annotate(str(i + 1), (c, r), color="yellow", xytext=(4, -4), textcoords="offset points")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(label, fontsize=9)
    for i, (r, c) in enumerate(pixels):
        ax = axes[0][i + extra]
        for method, img in spectra_by_method.items():
            colour, style = METHOD_STYLE.get(method, (None, "-"))
            ax.plot(wavelengths_nm, img[r, c], style, color=colour, lw=2.0 if method == "gt" else 1.2,
                    label=labels.get(method, method))
        ax.set_title(f"pixel {i + 1} (row {r}, col {c})", fontsize=9)
        ax.set_xlabel("wavelength (nm)")
        ax.set_ylabel("radiance (relative)")
        ax.grid(alpha=0.3)
    axes[0][extra].legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)
