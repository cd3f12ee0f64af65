"""Every corpus family by name: this module imports each family's module (their ``@register``
fills :data:`~specgen_addon.corpus.families.base.FAMILIES` in import order), so
:data:`FAMILY_NAMES` holds them all, the classic recipe first."""

from __future__ import annotations

from specgen_addon.corpus.families import car_paint, lobes, sheen, thin_film, tinted_coat  # noqa: F401  (registers them)
from specgen_addon.corpus.families.base import family_names

#: Every family name, the classic recipe first.
FAMILY_NAMES: tuple[str, ...] = family_names()
