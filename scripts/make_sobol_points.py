"""Precompute the scrambled Sobol point sets of the reference renderer's environment sampling.

The renderer draws its per-strategy uniforms from scipy's Owen-scrambled Sobol generator
(``scipy.stats.qmc.Sobol(d=2, scramble=True, seed=s).random(n)``). A stock Blender has no scipy, so
the sets the shipped sampling settings use are stored in ``specgen_addon/render/sobol_points.npz``
(scipy stays the single source: this script regenerates the file, a test compares it):

    python scripts/make_sobol_points.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from specgen_addon.render.sampling import SOBOL_TABLE, SOBOL_TABLE_COUNTS, SOBOL_TABLE_SEEDS, sobol_scipy  # noqa: E402


def main() -> int:
    arrays = {f"n{n}_s{s}": sobol_scipy(n, s).astype(np.float64)
              for n in SOBOL_TABLE_COUNTS for s in SOBOL_TABLE_SEEDS}
    np.savez_compressed(SOBOL_TABLE, **arrays)
    print(f"{SOBOL_TABLE}: {len(arrays)} point sets, {SOBOL_TABLE.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
