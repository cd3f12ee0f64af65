"""Measured complex indices of refraction ``(η, k)(λ)`` of metals, for conductor Fresnel.

The tables in ``data/ior/*.csv`` are copied number for number from the Mitsuba 3 wheel
(``mitsuba/data/ior``), which took them from the luxpop.com optical-constants database; their
headers name the underlying measurements (Palik, *Handbook of Optical Constants of Solids*, 1985,
and LLNL/CXRO compilations). Each file keeps that provenance in its comment header. Values are
interpolated linearly in wavelength and held constant outside the tabulated range.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import SpecGenError

IOR_DIR = Path(__file__).resolve().parent / "data" / "ior"

#: Metals shipped with the corpus (one CSV each); the split each belongs to is set in
#: :mod:`specgen_addon.corpus.spectra_sources`.
METALS: tuple[str, ...] = ("Ag", "Al", "Au", "Cr", "Cu", "Ir", "Mo", "Ni", "Rh", "W")


@functools.lru_cache(maxsize=None)
def _table(metal: str) -> np.ndarray:
    if metal not in METALS:
        raise SpecGenError(f"unknown metal {metal!r}; known: {', '.join(METALS)}")
    lines = [line for line in (IOR_DIR / f"{metal}.csv").read_text().splitlines()
             if line.strip() and not line.startswith("#")]
    if lines[0].replace(" ", "") != "wavelength_nm,eta,k":
        raise SpecGenError(f"{metal}.csv: expected the header 'wavelength_nm,eta,k'")
    rows = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    rows = rows[np.argsort(rows[:, 0])]
    rows.setflags(write=False)
    return rows


def metal_ior(metal: str, wavelengths_nm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real and imaginary parts ``(η, k)`` of ``metal``'s index at ``wavelengths_nm``."""
    t = _table(metal)
    w = np.asarray(wavelengths_nm, dtype=np.float64)
    return np.interp(w, t[:, 0], t[:, 1]), np.interp(w, t[:, 0], t[:, 2])


def metal_source(metal: str) -> str:
    """The provenance header (comment lines) of ``metal``'s table, for manifests and docs."""
    _table(metal)
    lines = (IOR_DIR / f"{metal}.csv").read_text().splitlines()
    return "\n".join(line[1:].strip() for line in lines if line.startswith("#"))
