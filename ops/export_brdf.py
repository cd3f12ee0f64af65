"""*Export BRDF*: the panel's material written as RGL ``.bsdf`` (spectral), MERL ``.binary`` (RGB)
or SpecGen ``.npz``, from the compact material file Generate keeps beside its lookups
(:mod:`specgen_addon.brdf.formats.export`, as ``infer -o FILE`` writes them)."""

from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ExportHelper

from specgen_addon.brdf.formats.export import OUTPUT_SUFFIXES
from specgen_addon.common.errors import SpecGenError

from . import naming
from .reporting import report_exception


def material_file(mat) -> Path:
    """The compact material file of a SpecGen material (``<stem>.npz`` beside its lookups)."""
    from .travel import _absolute

    if mat is None or "specgen_atlas" not in mat:
        raise SpecGenError("choose a SpecGen material first")
    atlas = Path(_absolute(str(mat["specgen_atlas"])))
    path = atlas.parent / f"{naming.atlas_stem(atlas)}.npz"
    if not path.is_file():
        raise SpecGenError(f"material {mat.name!r} has no BRDF file beside its lookups ({path.name}); "
                           "turn on Export Table and Generate it again")
    return path


class SPECGEN_OT_export_brdf(bpy.types.Operator, ExportHelper):
    """Write the material's BRDF for other renderers: RGL .bsdf (spectral, e.g. Mitsuba 3) or MERL .binary (RGB)"""

    bl_idname = "specgen.export_brdf"
    bl_label = "Export BRDF"
    bl_options = {"REGISTER"}
    filename_ext = ".bsdf"
    filter_glob: StringProperty(default=";".join(f"*{s}" for s in OUTPUT_SUFFIXES), options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        return context.scene.specgen.material is not None

    def execute(self, context):
        from specgen_addon.brdf.formats.export import check_output, write_output
        from specgen_addon.brdf.table import BRDFTable

        try:
            out = Path(bpy.path.abspath(self.filepath))
            check_output(out)
            table = BRDFTable.load(material_file(context.scene.specgen.material))
            line = write_output(table, out, overwrite=True)   # the file browser asked before replacing
        except Exception as exc:
            return report_exception(self, exc, "Export BRDF")
        self.report({"INFO"}, f"SpecGen: {line}")
        return {"FINISHED"}


CLASSES = (SPECGEN_OT_export_brdf,)
register, unregister = bpy.utils.register_classes_factory(CLASSES)
