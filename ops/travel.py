"""SpecGen materials travel with their .blend: lookups beside it, referred to by relative paths.

A material's lookups are files (an OSL Script node reads them by path, so Blender's Pack cannot
take them). On every save (``save_pre``, with the file's new path):

* a material whose files are still in the temporary folder of an unsaved file (see
  :func:`ops.properties.output_dir`) has its set of files (lookups, their JSON, preview,
  compact material) moved into ``specgen/`` beside the .blend;
* the paths it stores become relative to the .blend (``//specgen/…``), as Blender stores its own.

On every load (``load_post``) the Script node gets the absolute path of the lookups again, so a
.blend moved together with its ``specgen/`` folder (to another folder or machine) renders the
same. Missing lookups are baked again from the material's compact file (``<stem>.npz``, which
Generate writes beside them) when it is there; otherwise they are reported by material and file
name (and the spectral render refuses to start with the same sentence), never rendered black
without a word.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import bpy
from bpy.app.handlers import persistent

from specgen_addon.common.errors import SpecGenError

from . import naming

#: The folder beside the .blend that takes the lookups of an unsaved file on its first save.
FOLDER = "specgen"


def _specgen_materials() -> list:
    from .render import is_specgen_material

    return [m for m in bpy.data.materials if is_specgen_material(m) and "specgen_atlas_groups" in m]


def _absolute(path: str, blend_dir: str | None = None) -> str:
    """``path`` made absolute: ``//`` relative to ``blend_dir`` (default: the open file's folder)."""
    if path.startswith("//"):
        base = blend_dir if blend_dir is not None else os.path.dirname(bpy.data.filepath)
        return os.path.normpath(os.path.join(base, path[2:]))
    return path


def _relative(path: str, blend_dir: str) -> str:
    """``//…`` relative to ``blend_dir`` (a path on another drive stays absolute)."""
    try:
        return "//" + Path(os.path.relpath(path, blend_dir)).as_posix()
    except ValueError:  # Windows: another drive
        return path


def atlas_groups(mat) -> list[str]:
    """The absolute paths of a material's lookups (stored relative to the .blend once saved)."""
    return [_absolute(p) for p in mat["specgen_atlas_groups"]]


def _in_unsaved_folder(path: str) -> bool:
    """Whether ``path`` lies in the folder an unsaved file's lookups go to."""
    temp = os.path.abspath(os.path.join(tempfile.gettempdir(), FOLDER))
    try:
        return os.path.commonpath([os.path.abspath(path), temp]) == temp
    except ValueError:  # Windows: another drive
        return False


def _move_set(mat, old_dir: Path, new_dir: Path) -> None:
    """Move the material's set of files (:func:`ops.naming.files_of`) from ``old_dir`` to ``new_dir``."""
    stem = Path(str(mat["specgen_atlas"])).name.removesuffix("_lookup.exr")
    new_dir.mkdir(parents=True, exist_ok=True)
    for f in naming.files_of(old_dir, stem):
        target = new_dir / f.name
        if target.exists():
            raise OSError(f"{target} already exists")
        shutil.move(str(f), str(target))


def relocate(blend_path: str) -> list[str]:
    """What ``save_pre`` does for the .blend being written to ``blend_path``; returns warnings."""
    from .render import script_node

    blend_dir = os.path.dirname(os.path.abspath(blend_path))
    warnings = []
    for mat in _specgen_materials():
        groups = [_absolute(p) for p in mat["specgen_atlas_groups"]]
        atlas = _absolute(str(mat["specgen_atlas"]))
        if groups and _in_unsaved_folder(groups[0]):
            old_dir, new_dir = Path(groups[0]).parent, Path(blend_dir) / FOLDER
            try:
                _move_set(mat, old_dir, new_dir)
            except OSError as exc:
                warnings.append(f"SpecGen: the lookups of {mat.name!r} stay in {old_dir} ({exc})")
            else:
                groups = [str(new_dir / Path(p).name) for p in groups]
                atlas = str(new_dir / Path(atlas).name)
                for img in bpy.data.images:   # the preview went with them
                    if img.filepath and _in_unsaved_folder(bpy.path.abspath(img.filepath)) \
                            and (new_dir / Path(img.filepath).name).is_file():
                        img.filepath = _relative(str(new_dir / Path(img.filepath).name), blend_dir)
        mat["specgen_atlas_groups"] = [_relative(p, blend_dir) for p in groups]
        mat["specgen_atlas"] = _relative(atlas, blend_dir)
        node = script_node(mat)
        if node is not None and node.inputs["Atlas"].default_value:
            node.inputs["Atlas"].default_value = groups[0]
    return warnings


def missing_lookups(materials=None) -> list[str]:
    """One sentence per material (default: every SpecGen material) whose lookups are not where it says."""
    out = []
    for mat in _specgen_materials() if materials is None else materials:
        gone = [p for p in atlas_groups(mat) if not os.path.isfile(p)]
        if gone:
            out.append(f"material {mat.name!r}: baked lookup {gone[0]} is missing "
                       f"(move the {FOLDER}/ folder with the .blend, or Generate again)")
    return out


def rebuild(mat) -> str | None:
    """Bake a material's missing lookups again from its compact material file (``<stem>.npz``
    beside them, which Generate writes) and rebuild the material; what was done, or None."""
    import numpy as np

    from specgen_addon.bake import lookup as bake
    from specgen_addon.brdf.table import BRDFTable

    from .render import make_material, script_node

    atlas = Path(_absolute(str(mat["specgen_atlas"])))
    stem = atlas.name.removesuffix("_lookup.exr")
    source = atlas.parent / f"{stem}.npz"
    node = script_node(mat)
    if not source.is_file() or node is None:
        return None
    info = bake.bake_atlas(BRDFTable.load(source), atlas, wavelengths_nm=np.asarray(mat["specgen_wavelengths_nm"]),
                           n_phi_d=int(node.inputs["PhiD"].default_value))
    bake.save_atlas_info(info, naming.lookup_json(atlas.parent, stem))
    make_material(mat.name, info)
    if bpy.data.filepath:
        blend_dir = os.path.dirname(bpy.data.filepath)
        mat["specgen_atlas_groups"] = [_relative(str(p), blend_dir) for p in info.group_paths]
        mat["specgen_atlas"] = _relative(str(atlas), blend_dir)
    return f"the lookups of {mat.name!r} were missing and were baked again from {source}"


def reconnect() -> list[str]:
    """What ``load_post`` does: point every Script node at its lookups' absolute path, bake missing
    lookups again from the compact material where it is there; warnings for what is still missing."""
    from .render import script_node

    notes = []
    for mat in _specgen_materials():
        if missing_lookups([mat]):
            try:
                done = rebuild(mat)
            except (SpecGenError, OSError) as exc:  # a damaged material file: reported below as missing
                done = None
                notes.append(f"material {mat.name!r}: cannot bake its lookups again ({exc})")
            if done:
                notes.append(done)
        node = script_node(mat)
        groups = atlas_groups(mat)
        if node is not None and groups:
            node.inputs["Atlas"].default_value = groups[0]
    return notes + missing_lookups()


@persistent
def _save_pre(filepath, *_args) -> None:
    path = filepath if isinstance(filepath, str) and filepath else bpy.data.filepath
    if path:
        for warning in relocate(path):
            print(warning)


@persistent
def _load_post(*_args) -> None:
    for warning in reconnect():
        print(f"SpecGen: {warning}")


def register() -> None:
    if _save_pre not in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.append(_save_pre)
    if _load_post not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_load_post)


def unregister() -> None:
    for handlers, fn in ((bpy.app.handlers.save_pre, _save_pre), (bpy.app.handlers.load_post, _load_post)):
        if fn in handlers:
            handlers.remove(fn)
