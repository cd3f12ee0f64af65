"""Regenerate ``specgen_addon/data/colour_tables.npz`` from colour-science (build time).

    .venv/bin/python scripts/make_colour_tables.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from specgen_addon.colour_tables import write_tables  # noqa: E402

if __name__ == "__main__":
    path = write_tables()
    print(f"{path} ({path.stat().st_size / 1024:.1f} KiB)")
