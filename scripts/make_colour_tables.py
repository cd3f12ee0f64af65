"""Regenerate ``specgen_addon/spectral/data/colour_tables.npz`` from colour-science (build time).

    .venv/bin/python scripts/make_colour_tables.py
"""

from __future__ import annotations



from specgen_addon.spectral.colour_tables import write_tables  # noqa: E402

if __name__ == "__main__":
    path = write_tables()
    print(f"{path} ({path.stat().st_size / 1024:.1f} KiB)")
