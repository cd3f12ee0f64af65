"""Per-material result rows of the bench scripts, grouped by corpus family for their summary tables."""

from __future__ import annotations

from typing import Iterator


def family_groups(rows: list[dict], total: str = "all") -> Iterator[tuple[str, list[dict]]]:
    """``(family, its rows)`` in the order the families first appear, then ``(total, every row)``."""
    for family in dict.fromkeys(r["family"] for r in rows):
        yield family, [r for r in rows if r["family"] == family]
    yield total, rows
