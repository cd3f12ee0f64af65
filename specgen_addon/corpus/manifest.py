"""Corpus manifest: one JSON file with every material's parameters and split."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Sequence

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.corpus.material import Material
from specgen_addon.corpus.families import material_from_dict

MANIFEST_FORMAT = "specgen-corpus"
MANIFEST_VERSION = 1


def save_manifest(path: str | os.PathLike, materials: Sequence, seed: int | None = None,
                  overwrite: bool = False) -> Path:
    """Write ``materials`` to ``path`` (JSON) atomically; returns the path."""
    path = Path(path)
    counts = {s: sum(m.split == s for m in materials) for s in ("train", "val", "test")}
    doc = {"format": MANIFEST_FORMAT, "version": MANIFEST_VERSION, "seed": seed,
           "count": len(materials), "splits": counts,
           "materials": [m.to_dict() for m in materials]}
    with atomic_write(path, overwrite=overwrite) as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
    return path


def load_manifest(path: str | os.PathLike) -> list[Material]:
    """Materials of a manifest written by :func:`save_manifest`; SpecGenError if unreadable."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SpecGenError(f"{path}: not a readable corpus manifest ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != MANIFEST_FORMAT:
        raise SpecGenError(f"{path}: not a SpecGen corpus manifest")
    if doc.get("version") != MANIFEST_VERSION:
        raise SpecGenError(f"{path}: unsupported manifest version {doc.get('version')}")
    try:
        return [material_from_dict(d) for d in doc["materials"]]
    except SpecGenError as exc:
        raise SpecGenError(f"{path}: {exc}") from None


def find_material(materials: Sequence[Material], name: str) -> Material:
    """The material called ``name``; SpecGenError listing a few names if absent."""
    for m in materials:
        if m.name == name:
            return m
    raise SpecGenError(f"no material {name!r} in the corpus (e.g. "
                       f"{', '.join(m.name for m in materials[:5])})")
