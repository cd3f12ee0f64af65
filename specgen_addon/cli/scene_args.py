"""Command-line values of a whole-scene render: frame ranges and photo-to-object assignments.

``--frames 1-10`` or ``1,3,5-7`` (:func:`parse_frames`); ``--apply IMG:OBJECT`` with optional
photo-lighting options per photo, ``IMG:OBJECT:env=forest,rotation=30,exposure=2,key-light=on``
(:func:`parse_apply`). Both are checked completely before any work, and every error is one
sentence. No bpy: the object checks against a scene are the caller's (:func:`check_objects`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from specgen_addon.common.errors import SpecGenError

MAX_FRAMES = 100_000
_RANGE = re.compile(r"^\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?$")
#: Per-photo options of ``--apply`` and the lighting argument each one sets.
APPLY_OPTIONS = {"env": "env", "rotation": "rotation_deg", "exposure": "exposure",
                 "key-light": "key_light"}
_TRUE, _FALSE = {"on", "yes", "true", "1"}, {"off", "no", "false", "0"}


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
    """One ``--apply`` value: the photo, the object to give its material, and the photo's lighting
    (``None`` entries: the command's own ``--input-*`` options)."""

    image: Path
    object_name: str
    env: str | None = None
    rotation_deg: float | None = None
    exposure: float | None = None
    key_light: bool | None = None

    def lighting_args(self, defaults: Mapping[str, object]) -> dict:
        """Keyword arguments of :func:`specgen_addon.photo.photo_lighting.parse_lighting`, this photo's
        options over ``defaults`` (keys ``env``, ``rotation_deg``, ``exposure``, ``key_light``)."""
        out = dict(defaults)
        for key in ("env", "rotation_deg", "exposure", "key_light"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        return out


def _option(spec: str, key: str, value: str):
    if key not in APPLY_OPTIONS:
        raise SpecGenError(f"--apply {spec!r}: unknown option {key!r} (known: "
                           f"{', '.join(APPLY_OPTIONS)})")
    if key == "env":
        if not value:
            raise SpecGenError(f"--apply {spec!r}: env needs a map name or an HDRI file")
        return value
    if key == "key-light":
        if value.lower() not in _TRUE | _FALSE:
            raise SpecGenError(f"--apply {spec!r}: key-light must be on or off, not {value!r}")
        return value.lower() in _TRUE
    try:
        return float(value)
    except ValueError:
        raise SpecGenError(f"--apply {spec!r}: {key} must be a number, not {value!r}") from None


def parse_apply(spec: str) -> ApplySpec:
    """``IMG:OBJECT`` or ``IMG:OBJECT:key=value,...`` (split from the right, so a Windows drive
    letter in IMG is fine; an object name may not contain ':')."""
    head, opts = spec, {}
    first, sep, last = spec.rpartition(":")
    if sep and "=" in last:
        head = first
        for item in last.split(","):
            key, eq, value = item.partition("=")
            key = key.strip().lower()
            if not eq:
                raise SpecGenError(f"--apply {spec!r}: options are key=value pairs separated by commas")
            if APPLY_OPTIONS.get(key) in opts:
                raise SpecGenError(f"--apply {spec!r}: option {key!r} is given twice")
            opts[APPLY_OPTIONS.get(key, key)] = _option(spec, key, value.strip())
    image, sep, obj = head.rpartition(":")
    if not sep or not image or not obj.strip():
        raise SpecGenError(f"--apply {spec!r}: expected IMAGE:OBJECT (optionally "
                           f":env=NAME,rotation=DEG,exposure=X,key-light=on)")
    return ApplySpec(Path(image), obj.strip(), **opts)


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
