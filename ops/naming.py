"""Names of the datablocks and files one SpecGen material owns (no bpy: testable anywhere).

Each Generate makes one *set*, found from its stem ``<stem>`` (e.g. ``sphere``, ``sphere.001``):

* material ``SpecGen <stem>`` (its custom properties hold the spectral basis) and a shader node
  group of the same name (:func:`group_name`) whose OSL Script node reads the lookups;
* preview image ``SpecGen <stem> preview`` (the numpy-rendered sphere, :mod:`specgen_addon.bake.preview`);
* files in the output folder: ``<stem>_lookup.gNN.exr`` (lookups), ``<stem>_lookup.json`` (basis
  and layout), ``<stem>_preview.png``, and ``<stem>.npz`` only when the table is exported; with
  the photo options also ``<stem>_probe.exr`` (a chrome ball unwrapped), ``<stem>_scene_env.exr``
  (the scene's world, lit like this scene) and ``<stem>_circle.png`` (the circle preview).

With *Replace Materials* off a new Generate never reuses a stem that has a material, a node group
or files; with it on, the stem of the input is reused and its set replaced when the set is this
.blend's own (its material here names those files) or there is none, and never when the files in
the folder are another .blend's (two .blend files beside each other share ``//specgen/``).

Stems are safe on every system Blender runs on: ASCII (accents dropped, ``Kugel Öl`` →
``Kugel_Ol``), never a Windows device name (``con`` → ``con_``), and told apart from existing files
without regard to case (``Sphere`` and ``sphere`` are one file on Windows and macOS).

A spectral render is named after the scene, the camera and the frame
(:func:`render_output_name`, ``Scene_Camera_f0001.exr``); *Replace Outputs* decides whether an
existing one may be replaced.
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path
from typing import Callable, Iterable

PREFIX = "SpecGen"
MAX_STEM = 48
#: Names Windows keeps for devices, whatever the extension (``con.npz`` cannot be a file there).
WINDOWS_DEVICES = frozenset({"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)),
                             *(f"LPT{i}" for i in range(1, 10))})


def clean_stem(raw: str) -> str:
    """A file- and datablock-safe stem from an image or file name (``"my photo.png"`` → ``my_photo``)."""
    return clean_name(Path(raw).stem if "." in Path(raw).name else Path(raw).name, "brdf")


def clean_name(raw: str, fallback: str) -> str:
    """A file-safe version of a datablock name (``"cam.001"`` → ``cam_001``), ``fallback`` if empty:
    accents dropped (``Ö`` → ``O``), other characters but letters, digits, ``_`` and ``-`` made ``_``,
    and a Windows device name given a trailing ``_``."""
    ascii_ = unicodedata.normalize("NFKD", raw).encode("ascii", "ignore").decode("ascii")
    name = re.sub(r"[^A-Za-z0-9_\-]+", "_", ascii_).strip("_")[:MAX_STEM] or fallback
    return f"{name}_" if name.upper() in WINDOWS_DEVICES else name


def material_name(stem: str) -> str:
    return f"{PREFIX} {stem}"


def group_name(stem: str) -> str:
    """The set's node group: named as its material (materials and node groups are separate
    namespaces in Blender)."""
    return material_name(stem)


def preview_name(stem: str) -> str:
    return f"{PREFIX} {stem} preview"


def atlas_stem(atlas: str | Path) -> str:
    """The set's stem from its atlas path (``…/sphere.001_lookup.exr`` → ``sphere.001``)."""
    return Path(str(atlas)).name.removesuffix("_lookup.exr")


def lookup_json(out_dir: str | Path, stem: str) -> Path:
    return Path(out_dir) / f"{stem}_lookup.json"


def preview_png(out_dir: str | Path, stem: str) -> Path:
    return Path(out_dir) / f"{stem}_preview.png"


def probe_exr(out_dir: str | Path, stem: str) -> Path:
    """The room's environment unwrapped from a chrome ball photo."""
    return Path(out_dir) / f"{stem}_probe.exr"


def scene_env_exr(out_dir: str | Path, stem: str) -> Path:
    """The scene's world seen from its camera, the photo's panorama for "lit like this scene"."""
    return Path(out_dir) / f"{stem}_scene_env.exr"


def circle_png(out_dir: str | Path, stem: str) -> Path:
    """The photo with the circle used drawn on it."""
    return Path(out_dir) / f"{stem}_circle.png"


def files_of(out_dir: str | Path, stem: str) -> list[Path]:
    """Existing files of the set ``stem`` in ``out_dir``, named in any case (one file on Windows
    and macOS)."""
    out = Path(out_dir)
    if not out.is_dir():
        return []
    key = stem.casefold()
    names = {f"{key}{end}" for end in ("_preview.png", ".npz", "_probe.exr", "_scene_env.exr", "_circle.png")}
    return sorted(p for p in out.iterdir()
                  if p.name.casefold().startswith(f"{key}_lookup") or p.name.casefold() in names)


def unique_stem(base: str, taken: Callable[[str], bool]) -> str:
    """``base`` if free, else ``base.001``, ``base.002`` … (Blender's own numbering)."""
    if not taken(base):
        return base
    for i in range(1, 1000):
        candidate = f"{base}.{i:03d}"
        if not taken(candidate):
            return candidate
    raise RuntimeError(f"no free name for {base!r}")


def stem_for_generate(source: str, out_dir: str | Path, overwrite: bool,
                      material_names: Iterable[str], group_names: Iterable[str] = (),
                      owned: Callable[[str], bool] = lambda stem: False) -> str:
    """The stem a Generate of ``source`` uses: with Replace Materials on, the input's own when its
    files in ``out_dir`` are this .blend's (``owned(stem)``: a material here names them) or there
    are none; else the first whose material, node group and files do not exist yet."""
    base = clean_stem(source)
    if overwrite and (owned(base) or not files_of(out_dir, base)):
        return base
    materials = {m.casefold() for m in material_names}
    groups = {g.casefold() for g in group_names}
    return unique_stem(base, lambda s: material_name(s).casefold() in materials
                       or group_name(s).casefold() in groups or bool(files_of(out_dir, s)))


def render_output_name(scene: str, camera: str | None, frame: int) -> str:
    """The spectral EXR of one render: ``<scene>_<camera>_f0001.exr`` (names made file-safe;
    the preview PNG is ``<…>_preview.png`` beside it)."""
    cam = clean_name(camera or "", "nocamera")
    sign = "-" if frame < 0 else ""
    return f"{clean_name(scene, 'scene')}_{cam}_f{sign}{abs(int(frame)):04d}.exr"
