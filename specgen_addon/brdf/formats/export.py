"""Write a tabulated BRDF in the form its user asked for, and say what was written.

* ``.npz``: SpecGen's compact material file by default (:mod:`specgen_addon.brdf.material_file`), the
  full float32 table with ``full_table``.
* ``.bsdf``: an isotropic RGL tensor file (Dupuy & Jakob 2018), spectral where the table is, which
  Mitsuba 3's ``measured`` plugin renders (:func:`table_to_rgl`).
* ``.binary``: a MERL file (RGB; a spectral table is projected under D65 first).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.brdf.table import BRDFTable
from specgen_addon.brdf.formats.merl import write_merl
from specgen_addon.brdf.formats.rgl import write_rgl

#: What ``tabulate`` and ``infer`` write: a SpecGen table, RGL, MERL.
OUTPUT_SUFFIXES = (".npz", ".bsdf", ".binary")

#: The RGL layout of an exported file: incident-elevation slices and the square grid's size.
RGL_SLICES = 24
RGL_GRID = 64


def size_text(n_bytes: int) -> str:
    """``12.3 MB`` (decimal megabytes) or ``45.6 kB``."""
    return f"{n_bytes / 1e6:.1f} MB" if n_bytes >= 1e5 else f"{n_bytes / 1e3:.1f} kB"


def check_output(path: Path) -> None:
    """Refuse an output suffix this module cannot write, before any work."""
    if path.suffix.lower() not in OUTPUT_SUFFIXES:
        raise SpecGenError(f"{path}: output must end in {' or '.join(OUTPUT_SUFFIXES)}")


def table_to_rgl(table: BRDFTable, path: str | os.PathLike, overwrite: bool = False,
                 slices: int = RGL_SLICES, grid: int = RGL_GRID) -> Path:
    """Write ``table`` as an isotropic RGL ``.bsdf`` file (spectral tables keep their bands).

    The file's VNDF is uniform, so its warp is the identity and a sample's unit coordinates are
    those of the half vector itself, ``u = (√(θm·2/π), (φm − φi + π)/2π)``; the NDF is 1 and the
    projected area ¼, so the ``D/(4σ)`` factor is 1. Each node then holds ``fr·cos θo`` at the
    direction pair it stands for (what the format stores), ``θi`` at ``slices`` elevations from 0
    to 87°, on a ``grid``² square.
    """
    theta_i = np.linspace(0.0, np.radians(87.0), slices)
    u = np.linspace(0.0, 1.0, grid)
    theta_m = u ** 2 * (np.pi / 2)
    phi_m = u * 2 * np.pi - np.pi
    TM, PM = np.meshgrid(theta_m, phi_m, indexing="xy")        # [y=φ, x=θ]
    wm = np.stack([np.sin(TM) * np.cos(PM), np.sin(TM) * np.sin(PM), np.cos(TM)], -1).reshape(-1, 3)
    wl = table.wavelengths
    out = np.zeros((1, slices, table.n_channels, grid, grid), dtype=np.float32)
    for s, ti in enumerate(theta_i):
        wi = np.array([np.sin(ti), 0.0, np.cos(ti)])
        wo = 2.0 * (wm @ wi)[:, None] * wm - wi
        wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
        ok = wo[:, 2] > 1e-6
        vals = np.zeros((wm.shape[0], table.n_channels), dtype=np.float64)
        vals[ok] = table.eval(np.broadcast_to(wi, (int(ok.sum()), 3)), wo[ok]) * wo[ok, 2:3]
        out[0, s] = vals.reshape(grid, grid, -1).transpose(2, 0, 1)
    weights = (np.full(table.n_channels, 1.0 / table.n_channels) if table.is_spectral
               else np.array([0.2126, 0.7152, 0.0722]))
    luminance = np.einsum("c,psc...->ps...", weights, out).astype(np.float32)   # (1, S, m, m)
    kwargs = ({"spectra": out, "wavelengths": wl} if table.is_spectral else {"rgb": out})
    desc = table.metadata.get("description", "SpecGen BRDF")
    return write_rgl(path, description=f"{desc} (exported by SpecGen)", theta_i=theta_i,
                     ndf=np.ones((2, 2)), sigma=np.full((2, 2), 0.25), vndf=np.ones((1, slices, 2, 2)),
                     luminance=luminance,
                     jacobian=True, overwrite=overwrite, **kwargs)


def write_output(table: BRDFTable, path: Path, overwrite: bool = False, full_table: bool = False) -> str:
    """Write ``table`` to ``path`` in the format its suffix names; one line saying what and how big."""
    check_output(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        table.save(path, overwrite=overwrite, compact=not full_table)
        kind = "full table" if full_table else "compact material"
    elif suffix == ".bsdf":
        table_to_rgl(table, path, overwrite=overwrite)
        kind = f"RGL .bsdf, {'spectral' if table.is_spectral else 'RGB'}"
    else:
        write_merl(path, table.to_rgb(), overwrite=overwrite)
        kind = "MERL .binary, RGB" + (" (D65 projection)" if table.is_spectral else "")
    return f"wrote {path} ({kind}, {size_text(path.stat().st_size)})"
