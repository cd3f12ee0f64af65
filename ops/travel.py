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
Generate writes beside them) when it is there, or from the copy packed into the .blend;
otherwise they are reported by material and file name (and the spectral render refuses to start
with the same sentence), never rendered black without a word.

*Pack Into .blend* (:class:`SPECGEN_OT_pack_materials`, in the panel's *Saving* section) stores
each material's compact file inside the .blend, so that the .blend alone travels: the lookups
(tens of MB, read by path) stay files, and are baked again from the packed copy where they are
missing. The bytes ride in an image datablock packed with ``Image.pack(data=…)``: Blender keeps
a packed file of any content through save and open, without decoding it, and *File → External
Data → Unpack Resources* writes it back as ``//specgen/<stem>.npz``, where it is looked for. A
Text datablock would need base64 (a third larger) and slows the Text editor.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty

from specgen_addon.brdf.formats.export import size_text
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.common.errors import SpecGenError

from . import naming

#: The folder beside the .blend that takes the lookups of an unsaved file on its first save.
FOLDER = "specgen"
#: Name prefix of the image datablock holding a material's packed compact file.
PACKED_PREFIX = "SpecGen packed "
#: The material's custom property naming that datablock.
PACKED_KEY = "specgen_packed"


def load_image(path: Path, name: str):
    """A new image datablock ``name`` of the file at ``path``. Blender reads a backslash in a POSIX
    path as a folder separator, so such a file is read from a temporary copy and packed into the
    .blend (its ``filepath`` still names the file)."""
    path = Path(path)
    if os.sep == "/" and "\\" in str(path):
        with tempfile.TemporaryDirectory(prefix="specgen_image_") as tmp:
            copy = Path(tmp) / path.name.replace("\\", "_")
            shutil.copyfile(path, copy)
            img = bpy.data.images.load(str(copy))
            img.pack()
        img.filepath_raw = str(path)
    else:
        img = bpy.data.images.load(str(path))
    img.name = name
    return img


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


def _move_set(stem: str, old_dir: Path, new_dir: Path) -> tuple[str, dict[str, str]]:
    """Move the set ``stem``'s files (:func:`ops.naming.files_of`) from ``old_dir`` to
    ``new_dir``, all or none; where ``new_dir`` holds a set of the same stem (another .blend's),
    under the first free stem (``sphere.001``). Gives (the stem it moved under, old → new
    absolute path of each file)."""
    from specgen_addon.bake import lookup as bake

    new_stem = naming.unique_stem(stem, lambda s: bool(naming.files_of(new_dir, s)))
    moves = [(f, new_dir / f"{new_stem}{f.name[len(stem):]}") for f in naming.files_of(old_dir, stem)]
    taken = next((t for _, t in moves if t.exists()), None)
    if taken is not None:
        raise OSError(f"{taken} already exists")
    new_dir.mkdir(parents=True, exist_ok=True)
    done: list[tuple[Path, Path]] = []
    try:
        for f, target in moves:
            shutil.move(str(f), str(target))
            done.append((f, target))
        described = naming.lookup_json(new_dir, new_stem)
        if described.is_file():        # the description names its textures where they now are
            bake.set_atlas_path(described, new_dir / f"{new_stem}_lookup.exr")
    except (OSError, SpecGenError):
        for f, target in reversed(done):   # all or none: a half-moved set is a broken material
            shutil.move(str(target), str(f))
        raise
    return new_stem, {os.path.normpath(str(f)): str(t) for f, t in moves}


def relocate(blend_path: str) -> list[str]:
    """What ``save_pre`` does for the .blend being written to ``blend_path``; returns warnings."""
    from .render import script_node

    blend_dir = os.path.dirname(os.path.abspath(blend_path))
    # Blender rebases a datablock's relative path from the folder the file was in to the new one
    # as it writes (Save As elsewhere): such paths are set relative to the old folder here;
    # custom properties are not rebased, so they are set relative to the new one
    datablock_dir = os.path.dirname(bpy.data.filepath) if bpy.data.filepath else blend_dir
    warnings = []
    moved: dict[str, str] = {}        # old → new absolute path of each file moved out of the temporary folder
    for mat in _specgen_materials():
        groups = [_absolute(p) for p in mat["specgen_atlas_groups"]]
        atlas = _absolute(str(mat["specgen_atlas"]))
        if groups and _in_unsaved_folder(groups[0]):
            old_dir, new_dir = Path(groups[0]).parent, Path(blend_dir) / FOLDER
            stem = naming.atlas_stem(atlas)
            try:
                new_stem, renamed = _move_set(stem, old_dir, new_dir)
            except (OSError, SpecGenError) as exc:
                warnings.append(f"SpecGen: the lookups of {mat.name!r} stay in {old_dir} ({exc})")
            else:
                moved.update(renamed)
                groups = [renamed.get(os.path.normpath(p), p) for p in groups]
                atlas = str(new_dir / f"{new_stem}_lookup.exr")
                if new_stem != stem:
                    warnings.append(f"SpecGen: the lookups of {mat.name!r} are saved as {new_stem}_… in "
                                    f"{new_dir}: the set named {stem} there is another .blend's")
                for img in bpy.data.images:   # the preview went with them
                    where = os.path.normpath(bpy.path.abspath(img.filepath)) if img.filepath else ""
                    if where in renamed:
                        img.filepath = _relative(renamed[where], datablock_dir)
        mat["specgen_atlas_groups"] = [_relative(p, blend_dir) for p in groups]
        mat["specgen_atlas"] = _relative(atlas, blend_dir)
        preview = bpy.data.images.get(str(mat.get("specgen_preview", "")))
        if preview is not None and preview.filepath and not preview.filepath.startswith("//"):
            preview.filepath = _relative(preview.filepath, datablock_dir)   # as the lookups: moves with the .blend
        img = packed_image(mat)
        if img is not None:   # Unpack Resources writes it where it is looked for
            img.filepath_raw = _relative(str(Path(atlas).parent / f"{naming.atlas_stem(atlas)}.npz"), datablock_dir)
        node = script_node(mat)
        if node is not None and node.inputs["Atlas"].default_value:
            node.inputs["Atlas"].default_value = groups[0]
    for scene in bpy.data.scenes:     # the last lookup baked, which Apply builds a material from
        s = getattr(scene, "specgen", None)
        if s is not None and s.atlas_json:
            path = scene_atlas_json(s)
            s.atlas_json = _relative(moved.get(os.path.normpath(path), path), blend_dir)
    return warnings


def scene_atlas_json(settings) -> str:
    """The absolute path of a scene's last baked lookup (``settings.atlas_json``, stored relative
    to the .blend once saved)."""
    return os.path.normpath(_absolute(settings.atlas_json))


def missing_lookups(materials=None) -> list[str]:
    """One sentence per material (default: every SpecGen material) whose lookups are not where it says."""
    out = []
    for mat in _specgen_materials() if materials is None else materials:
        gone = [p for p in atlas_groups(mat) if not os.path.isfile(p)]
        if gone:
            out.append(f"material {mat.name!r}: baked lookup {gone[0]} is missing "
                       f"(move the {FOLDER}/ folder with the .blend, or Generate again)")
    return out


def owns_set(out_dir: str, stem: str) -> bool:
    """Whether the set ``stem`` in ``out_dir`` is this .blend's: its material here names those
    lookups (another .blend beside this one may hold a set of the same stem in ``//specgen/``)."""
    mat = bpy.data.materials.get(naming.material_name(stem))
    if mat is None or "specgen_atlas" not in mat:
        return False
    here = os.path.normcase(os.path.normpath(_absolute(str(mat["specgen_atlas"]))))
    return here == os.path.normcase(os.path.normpath(os.path.join(out_dir, f"{stem}_lookup.exr")))


def check_lookups(materials, warn) -> None:
    """Before a render that reads the lookups: bake again those that are missing (from the compact
    material, beside them or packed; each note to ``warn``), then refuse, in one sentence naming
    the material and the file, lookups still missing or another Generate's."""
    for note in restore_missing(materials):
        warn(f"SpecGen: {note}")
    wrong = missing_lookups(materials) or replaced_lookups(materials)
    if wrong:
        raise SpecGenError(wrong[0])


def replaced_lookups(materials=None) -> list[str]:
    """One sentence per material (default: every SpecGen material) whose lookups on disk are
    another Generate's: a later run with *Replace Materials* rewrote them, then Undo brought the
    material back (undo restores datablocks, not files). Told apart by the spectral basis the
    material holds against the one its lookups' JSON holds."""
    import numpy as np

    from specgen_addon.bake import lookup as bake

    out = []
    for mat in _specgen_materials() if materials is None else materials:
        described = Path(_absolute(str(mat["specgen_atlas"]))).with_suffix(".json")
        try:
            on_disk = bake.load_atlas_info(described).basis.ravel()
        except SpecGenError:
            continue              # missing or unreadable: missing_lookups says so
        held = np.asarray(mat.get("specgen_basis", []), np.float64)
        if on_disk.shape != held.shape or not np.allclose(on_disk, held, rtol=1e-6, atol=1e-9):
            out.append(f"material {mat.name!r}: its lookups in {described.parent} were replaced by a later "
                       "Generate (undo brings back the material, not its files); Generate it again")
    return out


def compact_path(mat) -> Path:
    """Where a material's compact file (``<stem>.npz``) lies: beside its lookups."""
    atlas = Path(_absolute(str(mat["specgen_atlas"])))
    return atlas.parent / f"{naming.atlas_stem(atlas)}.npz"


def packed_image(mat):
    """The image datablock holding the material's packed compact file, or None."""
    name = mat.get(PACKED_KEY)
    img = bpy.data.images.get(name) if name else None
    return img if img is not None and img.packed_file is not None else None


def pack(mat) -> int:
    """Store the material's compact file inside the .blend (module docstring); its size in bytes.

    A material already packed keeps its copy unless the file beside it has changed (Generate with
    *Replace Materials*)."""
    _pack_preview(mat)
    source, img = compact_path(mat), packed_image(mat)
    if not source.is_file():
        if img is not None:
            return int(img.packed_file.size)
        raise SpecGenError(f"material {mat.name!r} has no compact material file to pack ({source} is "
                           "missing): Generate it again with Export Table on")
    data = source.read_bytes()
    if img is not None and int(img.packed_file.size) == len(data) and bytes(img.packed_file.data) == data:
        return len(data)
    if img is not None:
        bpy.data.images.remove(img)
    img = bpy.data.images.new(PACKED_PREFIX + source.stem, 1, 1)
    img.source = "FILE"
    img.filepath_raw = _relative(str(source), os.path.dirname(bpy.data.filepath)) if bpy.data.filepath \
        else str(source)
    img.pack(data=data, data_len=len(data))
    img.use_fake_user = True   # no material or node uses it: kept on save by its fake user
    mat[PACKED_KEY] = img.name
    return len(data)


def _pack_preview(mat) -> None:
    """The material's preview image (the panel's thumbnail, a few tens of kB) packed too, so a
    .blend copied alone shows it."""
    preview = bpy.data.images.get(str(mat.get("specgen_preview", "")))
    if preview is not None and preview.packed_file is None and preview.filepath \
            and os.path.isfile(bpy.path.abspath(preview.filepath)):
        preview.pack()


def unpack(mat) -> None:
    """Remove the material's packed compact file from the .blend (the file beside it stays), and
    its packed preview (read from its file again, or written back where that is gone)."""
    img = packed_image(mat)
    if img is not None:
        bpy.data.images.remove(img)
    if PACKED_KEY in mat:
        del mat[PACKED_KEY]
    preview = bpy.data.images.get(str(mat.get("specgen_preview", "")))
    if preview is not None and preview.packed_file is not None:
        preview.unpack(method="USE_ORIGINAL")


def _restore_packed(mat, source: Path) -> Path | None:
    """Write the packed compact file back to ``source`` (or, where that folder cannot be
    written, to the temporary folder that a later save moves beside the .blend); its path, or None."""
    img = packed_image(mat)
    if img is None:
        return None
    data = bytes(img.packed_file.data)
    # where the material says, if that folder is there; else beside this .blend (a file copied
    # alone); else the temporary folder (an unsaved file, or a folder that cannot be written)
    folders = [source.parent] if source.parent.is_dir() else []
    if bpy.data.filepath:
        folders.append(Path(os.path.dirname(bpy.data.filepath)) / FOLDER)
    for folder in folders + [Path(tempfile.gettempdir()) / FOLDER]:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with atomic_write(folder / source.name, overwrite=True) as tmp:
                tmp.write_bytes(data)
        except (OSError, SpecGenError):
            continue
        return folder / source.name
    return None


def rebuild(mat) -> str | None:
    """Bake a material's missing lookups again from its compact material file (``<stem>.npz``
    beside them, which Generate writes, or the copy packed into the .blend) and rebuild the
    material; what was done, or None."""
    import numpy as np

    from specgen_addon.bake import lookup as bake
    from specgen_addon.brdf.table import BRDFTable

    from .render import make_material, script_node

    atlas = Path(_absolute(str(mat["specgen_atlas"])))
    stem = naming.atlas_stem(atlas)
    source = atlas.parent / f"{stem}.npz"
    node = script_node(mat)
    if node is None:
        return None
    origin = str(source)
    if not source.is_file():
        restored = _restore_packed(mat, source)
        if restored is None:
            return None
        source, atlas = restored, restored.parent / atlas.name
        origin = f"the compact material packed into the .blend (written back to {source})"
    info = bake.bake_atlas(BRDFTable.load(source), atlas, wavelengths_nm=np.asarray(mat["specgen_wavelengths_nm"]),
                           n_phi_d=int(node.inputs["PhiD"].default_value))
    bake.save_atlas_info(info, naming.lookup_json(atlas.parent, stem))
    make_material(mat.name, info)
    if bpy.data.filepath:
        blend_dir = os.path.dirname(bpy.data.filepath)
        mat["specgen_atlas_groups"] = [_relative(str(p), blend_dir) for p in info.group_paths]
        mat["specgen_atlas"] = _relative(str(atlas), blend_dir)
    return f"the lookups of {mat.name!r} were missing and were baked again from {origin}"


def restore_missing(materials=None) -> list[str]:
    """Bake again, from the compact material (beside the lookups or packed), the lookups that are
    missing (default: of every SpecGen material); what was done and what could not be."""
    notes = []
    for mat in _specgen_materials() if materials is None else materials:
        if missing_lookups([mat]):
            try:
                done = rebuild(mat)
            except (SpecGenError, OSError) as exc:  # a damaged material file: reported below as missing
                done = None
                notes.append(f"material {mat.name!r}: cannot bake its lookups again ({exc})")
            if done:
                notes.append(done)
    return notes


def reconnect() -> list[str]:
    """What ``load_post`` does: point every Script node at its lookups' absolute path, bake missing
    lookups again from the compact material where it is there; warnings for what is still missing."""
    from .render import script_node

    notes = restore_missing()
    for mat in _specgen_materials():
        node = script_node(mat)
        groups = atlas_groups(mat)
        if node is not None and groups:
            node.inputs["Atlas"].default_value = groups[0]
    return notes + missing_lookups()


def packing_wanted() -> bool:
    """Whether the open file asks for its materials to be packed (any scene's *Pack Into .blend*)."""
    return any(getattr(sc, "specgen_pack", False) for sc in bpy.data.scenes)


def pack_all() -> tuple[int, int]:
    """Pack every SpecGen material (:func:`pack`); (materials packed, bytes)."""
    sizes = [pack(mat) for mat in _specgen_materials()]
    return len(sizes), sum(sizes)


def packed_total() -> tuple[int, int]:
    """(materials packed, bytes) in the open file."""
    imgs = [img for img in map(packed_image, _specgen_materials()) if img is not None]
    return len(imgs), sum(int(img.packed_file.size) for img in imgs)


class SPECGEN_OT_pack_materials(bpy.types.Operator):
    """Store each SpecGen material's compact file inside the .blend, so the .blend alone travels
    (its lookups are baked again from it where they are missing); Unpack removes the copies"""

    bl_idname = "specgen.pack_materials"
    bl_label = "Pack Materials Into .blend"
    bl_options = {"REGISTER", "UNDO"}

    unpack: BoolProperty(name="Unpack", default=False,
                         description="Remove the packed copies (the files beside the .blend stay)")

    def execute(self, context):
        for sc in bpy.data.scenes:
            sc.specgen_pack = not self.unpack
        if self.unpack:
            for mat in _specgen_materials():
                unpack(mat)
            self.report({"INFO"}, "SpecGen: materials no longer packed into the .blend")
            return {"FINISHED"}
        try:
            n, size = pack_all()
        except (SpecGenError, OSError) as exc:
            self.report({"ERROR"}, f"SpecGen: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"SpecGen: packed {n} material{'s' * (n != 1)} into the .blend ({size_text(size)}); "
                              "materials generated later are packed when the file is saved")
        return {"FINISHED"}


class SPECGEN_PT_saving(bpy.types.Panel):
    """Whether the materials' compact files travel inside the .blend."""

    bl_idname = "SPECGEN_PT_saving"
    bl_label = "Saving"
    bl_parent_id = "SPECGEN_PT_main"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "SpecGen"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        on = context.scene.specgen_pack
        op = layout.operator(SPECGEN_OT_pack_materials.bl_idname, text="Pack Into .blend", depress=on,
                             icon="PACKAGE" if on else "UGLYPACKAGE")
        op.unpack = on
        n, size = packed_total()
        layout.label(text=f"{n} material{'s' * (n != 1)} packed ({size_text(size)})" if n
                     else f"lookups read from //{FOLDER}/ beside the .blend")


@persistent
def _save_pre(filepath, *_args) -> None:
    path = filepath if isinstance(filepath, str) and filepath else bpy.data.filepath
    if path:
        for warning in relocate(path):
            print(warning)
    if packing_wanted():
        for mat in _specgen_materials():
            try:
                pack(mat)
            except (SpecGenError, OSError) as exc:
                print(f"SpecGen: {exc}")


def after_copy_saved(copy_path: str) -> None:
    """What ``save_post`` does after *Save Copy* (the open file stays what it was): the paths
    ``save_pre`` made relative to the copy's folder are made the open file's again (relative to
    its folder, or absolute while it is unsaved), so the session keeps finding the lookups that
    moved beside the copy."""
    copy_dir = os.path.dirname(os.path.abspath(copy_path))
    here = os.path.dirname(bpy.data.filepath) if bpy.data.filepath else None

    def mine(path: str) -> str:
        if not path.startswith("//"):
            return path
        where = _absolute(path, copy_dir)
        return _relative(where, here) if here else where

    for mat in _specgen_materials():
        mat["specgen_atlas_groups"] = [mine(str(q)) for q in mat["specgen_atlas_groups"]]
        mat["specgen_atlas"] = mine(str(mat["specgen_atlas"]))
    if here is None:   # an unsaved file's image paths were set relative to the copy as well
        for img in bpy.data.images:
            if img.filepath.startswith("//"):
                img.filepath_raw = mine(img.filepath)
    for scene in bpy.data.scenes:
        s = getattr(scene, "specgen", None)
        if s is not None and s.atlas_json:
            s.atlas_json = mine(s.atlas_json)


@persistent
def _save_post(filepath, *_args) -> None:
    path = filepath if isinstance(filepath, str) and filepath else ""
    if path and os.path.normpath(os.path.abspath(path)) != os.path.normpath(os.path.abspath(bpy.data.filepath or "/")):
        after_copy_saved(path)   # Save Copy: the open file is not the one written


@persistent
def _load_post(*_args) -> None:
    for warning in reconnect():
        print(f"SpecGen: {warning}")


_CLASSES = (SPECGEN_OT_pack_materials, SPECGEN_PT_saving)


def register() -> None:
    bpy.types.Scene.specgen_pack = BoolProperty(
        name="Pack Into .blend", default=False,
        description="Keep each SpecGen material's compact file inside the .blend when it is saved")
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    if _save_pre not in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.append(_save_pre)
    if _save_post not in bpy.app.handlers.save_post:
        bpy.app.handlers.save_post.append(_save_post)
    if _load_post not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_load_post)


def unregister() -> None:
    for handlers, fn in ((bpy.app.handlers.save_pre, _save_pre), (bpy.app.handlers.save_post, _save_post),
                         (bpy.app.handlers.load_post, _load_post)):
        if fn in handlers:
            handlers.remove(fn)
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    del bpy.types.Scene.specgen_pack
