"""Command-line values of a whole-scene render: frame ranges and photo-to-object assignments.

``--frames 1-10`` or ``1,3,5-7`` (:func:`parse_frames`); ``--apply IMG:OBJECT`` with optional
photo options per photo, any of ``infer``'s (``IMG:OBJECT:env=forest,rotation=30,key-light=on``,
``IMG:OBJECT:light=30,20,2,3200K,ambient=0.05,linear=on``; :func:`parse_apply`). Both are checked completely before any work, and every error is one
sentence. No bpy: the object checks against a scene are the caller's (:func:`check_objects`).
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from specgen_addon.cli.photo_args import apply_namespace, parse_apply_options, split_apply
from specgen_addon.common.errors import SpecGenError

MAX_FRAMES = 100_000
_RANGE = re.compile(r"^\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?$")


def parse_frames(text: str) -> list[int]:
    """Frames of ``"1-10"``, ``"1,3,5-7"`` or ``"12"``: sorted, each once."""
    frames: set[int] = set()
    for part in str(text).split(","):
        m = _RANGE.match(part)
        if m is None:
            raise SpecGenError(f"--frames {text!r}: expected frames like 1-10 or 1,3,5-7")
        a = int(m.group(1))
        b = a if m.group(2) is None else int(m.group(2))
        if b < a:
            raise SpecGenError(f"--frames {text!r}: range {a}-{b} runs backwards")
        if len(frames) + (b - a + 1) > MAX_FRAMES:
            raise SpecGenError(f"--frames {text!r}: more than {MAX_FRAMES} frames")
        frames.update(range(a, b + 1))
    return sorted(frames)


@dataclass(frozen=True)
class ApplySpec:
    """One ``--apply`` value: the photo, the object to give its material, and the photo's own
    options (``(dest, value)`` pairs of :mod:`specgen_addon.cli.photo_args`; the command's own
    values for the rest)."""

    image: Path
    object_name: str
    options: tuple[tuple[str, object], ...] = ()

    def namespace(self, base: argparse.Namespace) -> argparse.Namespace:
        """The command's values with this photo's options over them."""
        return apply_namespace(base, self.options)


def parse_apply(spec: str) -> ApplySpec:
    """``IMG:OBJECT`` or ``IMG:OBJECT:key=value,...``, every photo option of ``infer`` a key
    (``light=30,20,2,3200K``, ``linear=on``, ``light-probe=chrome.png`` ...; ``env``,
    ``rotation``, ``exposure``, ``key-light`` for the map); an object name may not contain ':'."""
    head, text = split_apply(spec)
    options = parse_apply_options(spec, text) if text else ()
    image, sep, obj = head.rpartition(":")
    if not sep or not image or not obj.strip():
        raise SpecGenError(f"--apply {spec!r}: expected IMAGE:OBJECT (optionally "
                           f":env=NAME,rotation=DEG,light=AZ,EL,... with any photo option of infer)")
    return ApplySpec(Path(image), obj.strip(), options)


def check_objects(specs: Iterable[ApplySpec], object_types: Mapping[str, str],
                  scene_name: str) -> None:
    """Every target object exists in the scene (``object_types``: name -> Blender type), is a
    mesh, and is named once."""
    seen: set[str] = set()
    for s in specs:
        if s.object_name in seen:
            raise SpecGenError(f"--apply: object {s.object_name!r} is given more than one photo")
        seen.add(s.object_name)
        kind = object_types.get(s.object_name)
        if kind is None:
            raise SpecGenError(f"--apply: scene {scene_name!r} has no object {s.object_name!r}")
        if kind != "MESH":
            raise SpecGenError(f"--apply: object {s.object_name!r} is a {kind.lower()}, not a mesh")
