"""Inputs of ``batch-many``: discovery, stable item names, and the resume plan.

An *item* is one input file (a photo of a sphere or a BRDF file) and the folder ``OUT/<id>/`` its
results live in. A finished item holds ``item.json`` with the input's fingerprint (path, size,
modification time) and the ``batch.py`` arguments it was made with; a rerun with the same input
and arguments skips it, anything else must be asked for with ``--overwrite``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterable, Sequence

from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo.read import FLOAT_SUFFIXES, RAW_SUFFIXES

#: 8/16-bit photo files (the photo reader decodes them through Pillow or OpenImageIO).
INTEGER_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".tga")
#: Photos of a sphere: ``batch.py --image``; the float and camera RAW suffixes are the photo
#: reader's own (:mod:`specgen_addon.photo.read`), so batch-many takes what ``infer`` reads.
IMAGE_SUFFIXES = INTEGER_IMAGE_SUFFIXES + FLOAT_SUFFIXES + RAW_SUFFIXES
#: BRDF files: spectral tables render directly, the rest go through :mod:`.prepare` first.
BRDF_SUFFIXES = (".npz", ".binary", ".bsdf")
#: The record a finished item leaves in its folder (written last, inside the atomic rename).
RECORD_NAME = "item.json"


@dataclass(frozen=True)
class Item:
    """One input and where its results go (``OUT/<id>/``)."""

    id: str
    input: str           #: absolute path of the input file
    kind: str            #: "image" (photo of a sphere) or "brdf" (BRDF file)
    size: int            #: bytes, part of the fingerprint
    mtime_ns: int        #: modification time, part of the fingerprint

    def fingerprint(self, batch_args: Sequence[str]) -> dict:
        """What decides whether an existing result is this item's: input identity + settings."""
        return {"input": self.input, "size": self.size, "mtime_ns": self.mtime_ns,
                "batch_args": list(batch_args)}

    def to_dict(self) -> dict:
        return asdict(self)


def input_kind(path: Path) -> str | None:
    """"image", "brdf" or None (not an input ``batch-many`` knows) from the file suffix."""
    suffix = path.suffix.lower()
    if suffix in IMAGE_SUFFIXES:
        return "image"
    if suffix in BRDF_SUFFIXES:
        return "brdf"
    return None


def read_manifest(path: Path) -> list[Path]:
    """Input paths listed in a manifest, relative paths taken from the manifest's folder.

    A ``.json`` manifest is a list of paths (or ``{"inputs": [...]}``); any other file has one
    path per line, blank lines and ``#`` comments ignored.
    """
    if path.is_dir():
        raise SpecGenError(f"{path}: is a folder, expected a manifest file (one path per line, or a "
                           "JSON list); to run every input in a folder, name the folder itself")
    if not path.is_file():
        raise SpecGenError(f"{path}: manifest not found")
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise SpecGenError(f"{path}: cannot read the manifest ({exc.strerror})") from None
    except UnicodeDecodeError:
        text = "\0"
    if "\0" in text:
        raise SpecGenError(f"{path}: not a text manifest (expected UTF-8 text: one path per line, "
                           "or a JSON list)")
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise SpecGenError(f"{path}: cannot parse the JSON manifest ({exc})") from None
        if isinstance(data, dict):
            data = data.get("inputs")
        if not isinstance(data, list) or not all(isinstance(p, str) for p in data):
            raise SpecGenError(f"{path}: a JSON manifest is a list of paths or {{\"inputs\": [...]}}")
        entries = data
    else:
        entries = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
        entries = [e for e in entries if e]
    return [p if p.is_absolute() else path.parent / p for p in map(Path, entries)]


def collect_inputs(paths: Iterable[Path], manifest: Path | None = None) -> list[Path]:
    """Input files from paths (a folder contributes its known inputs, sorted, not recursive) and
    a manifest; every named file must exist and have a known suffix. Duplicates are dropped."""
    named = list(paths) + (read_manifest(manifest) if manifest is not None else [])
    files: list[Path] = []
    for p in named:
        if p.is_dir():
            files += sorted(f for f in p.iterdir() if f.is_file() and input_kind(f))
        elif not p.is_file():
            raise SpecGenError(f"{p}: input not found")
        elif input_kind(p) is None:
            raise SpecGenError(f"{p}: not a known input (photos: "
                               f"{', '.join(INTEGER_IMAGE_SUFFIXES + FLOAT_SUFFIXES)} and camera RAW "
                               f"{', '.join(RAW_SUFFIXES)}; BRDF files: {', '.join(BRDF_SUFFIXES)})")
        else:
            files.append(p)
    seen: set[Path] = set()
    unique = []
    for f in files:
        r = f.resolve()
        if r not in seen:
            seen.add(r)
            unique.append(r)
    if not unique:
        raise SpecGenError("no inputs: name photos, BRDF files, folders holding them, or --manifest")
    return unique


#: Names batch-many itself uses in the output folder (compared case-insensitively); hidden
#: names (``.work``, lock files) are kept out by :func:`folder_name` too.
RESERVED_NAMES = ("failed", "report.json", "work")


def folder_name(stem: str) -> str:
    """An item folder name for a file stem that can never be one of batch-many's own entries:
    leading dots dropped (no hidden names, no ``.``/``..``), a name made only of dots becomes
    ``item``, and a reserved name gets ``_item`` appended."""
    name = stem.lstrip(".") or "item"
    if name.lower() in RESERVED_NAMES:
        name += "_item"
    return name


def make_items(files: Sequence[Path]) -> list[Item]:
    """Items with folder names that are stable for a given input list: the file stem (made safe
    by :func:`folder_name`), with the suffix added where two inputs share a stem, and a counter
    where they still collide."""
    stems: dict[str, int] = {}
    for f in files:
        stems[folder_name(f.stem)] = stems.get(folder_name(f.stem), 0) + 1
    used: set[str] = set()
    items = []
    for f in files:
        stem = folder_name(f.stem)
        name = stem if stems[stem] == 1 else f"{stem}_{f.suffix.lstrip('.').lower()}"
        base, n = name, 2
        while name.lower() in used:  # case-insensitive file systems too
            name, n = f"{base}_{n}", n + 1
        used.add(name.lower())
        st = f.stat()
        items.append(Item(name, str(f), input_kind(f) or "", st.st_size, st.st_mtime_ns))
    return items


@dataclass
class Plan:
    todo: list[Item]
    skipped: list[tuple[Item, dict]]   #: items already finished, with their records


def plan(items: Sequence[Item], out: Path, batch_args: Sequence[str], overwrite: bool = False) -> Plan:
    """Split items into those to run and those already finished with the same input and settings.

    An item folder made from another input or other settings is an error (nothing is run)
    unless ``overwrite``; so a rerun never silently replaces results.
    """
    todo, skipped = [], []
    for item in items:
        folder = out / item.id
        record_path = folder / RECORD_NAME
        if not folder.exists():
            todo.append(item)
            continue
        record = None
        if record_path.is_file():
            try:
                record = json.loads(record_path.read_text())
            except ValueError:
                record = None
        if record is not None and record.get("fingerprint") == item.fingerprint(batch_args):
            skipped.append((item, record))
        elif overwrite:
            todo.append(item)
        else:
            why = ("holds results of another input or other settings" if record is not None
                   else "exists and is not a batch-many result")
            raise SpecGenError(f"{folder}: {why} (pass --overwrite to redo it)")
    return Plan(todo, skipped)
