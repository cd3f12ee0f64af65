"""Scene settings of the SpecGen panel (``scene.specgen``)."""

from __future__ import annotations

import os
import tempfile

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from specgen_addon.bake.lookup import DEFAULT_TOLERANCE
from specgen_addon.generate.models import DEFAULT_MODEL, MODELS
from specgen_addon.spectral.spectra import DEFAULT_BAND_COUNT, DEFAULT_RANGE_NM
from .photo_properties import CLASSES as PHOTO_CLASSES
from .photo_properties import SpecGenPhotoSettings

LOOKUP_RESOLUTIONS = (
    ("180", "Full (180 φd)", "The whole MERL grid: 90 θh × 90 θd × 180 φd"),
    ("90", "Half (90 φd)", "Every second φd sample (smaller textures, slightly smoother)"),
    ("45", "Quarter (45 φd)", "Every fourth φd sample (previews)"),
)


RENDER_MODES = (
    ("FULL_SCENE", "Full Scene",
     "Cycles path-traces every object, light and the world (global illumination), three bands per "
     "render; direct light on SpecGen surfaces from the exact lookups, their bounces through the "
     "fitted native closures"),
    ("EXACT", "Exact (SpecGen Objects, Direct Light)",
     "The tabulated BRDF evaluated exactly in OSL, direct light from up to four sun/point lights "
     "and the world, on SpecGen objects only (for validation)"),
)


# "//" = relative to the .blend (Blender 4.5+ asks path properties to opt in)
_PATH = {"PATH_SUPPORTS_BLEND_RELATIVE"} if bpy.app.version >= (4, 5, 0) else set()


def _is_specgen_material(self, material) -> bool:
    return bool(material.get("specgen"))


def _update_range(self, context) -> None:
    if self.wl_max <= self.wl_min:
        self.wl_max = self.wl_min + 1.0


class SpecGenSettings(bpy.types.PropertyGroup):
    """Inputs, spectral sampling and render settings of one scene."""

    image: PointerProperty(name="Image", type=bpy.types.Image,
                           description="Photo of a sphere of the material (image datablock)")
    image_path: StringProperty(name="Image File", subtype="FILE_PATH", options=_PATH,
                               description="Photo of a sphere of the material (used if no datablock is set)")
    weights_path: StringProperty(name="Weights", subtype="FILE_PATH", options=_PATH,
                                 description="Network weights (.pt with its .onnx graphs); empty = the shipped networks (one for canonical renders, one for photos)")
    wl_min: FloatProperty(name="From", default=DEFAULT_RANGE_NM[0], min=360.0, max=1000.0,
                          precision=0, description="Shortest wavelength (nm)", update=_update_range)
    wl_max: FloatProperty(name="To", default=DEFAULT_RANGE_NM[1], min=360.0, max=1000.0,
                          precision=0, description="Longest wavelength (nm)", update=_update_range)
    bands: IntProperty(name="Bands", default=DEFAULT_BAND_COUNT, min=1, max=128,
                       description="Number of wavelength bands in the spectral output")
    lookup_resolution: EnumProperty(name="Lookup", items=LOOKUP_RESOLUTIONS, default="180",
                                    description="Resolution of the baked BRDF lookup textures")
    basis_tolerance: FloatProperty(name="Basis Tolerance", default=DEFAULT_TOLERANCE, min=0.0, max=0.1,
                                   precision=4, description="Relative RMS spectral error per table "
                                   "entry allowed when the spectra are compressed to a basis "
                                   "(0 = exact; each 4 more coefficients cost one more render)")
    render_mode: EnumProperty(name="Mode", items=RENDER_MODES, default="FULL_SCENE",
                              description="What Render Spectral Stack renders")
    samples: IntProperty(name="Samples", default=16, min=1, max=4096,
                         description="Cycles samples per pixel of each spectral render")
    resolution: IntProperty(name="Resolution", default=256, min=8, max=4096,
                            description="Width and height of the spectral render (pixels)")
    env_samples: IntProperty(name="Env Samples", default=2, min=1, max=64,
                             description="Environment directions the shader samples per Cycles sample")
    output_dir: StringProperty(name="Output", subtype="DIR_PATH", default="//specgen/", options=_PATH,
                               description="Folder for baked lookups and spectral EXR renders")
    overwrite: BoolProperty(name="Replace Materials", default=False,
                            description="Generate reuses the photo's name and replaces its SpecGen "
                            "material, node group and lookup files (off: a new numbered set)")
    overwrite_outputs: BoolProperty(name="Replace Outputs", default=False,
                                    description="Render Spectral Stack replaces an existing "
                                    "spectral EXR and preview of the same scene, camera and frame")
    quick_preview: BoolProperty(name="Quick Preview", default=False,
                                description="Render at 25 % resolution, at most 16 samples, no "
                                "denoising (this render only; the scene keeps its settings)")
    estimate: StringProperty(name="Estimate", default="", options={"HIDDEN"},
                             description="The last time estimate of a Full Scene render")
    model: EnumProperty(name="Model", default=DEFAULT_MODEL,
                        items=[(name, c.label, c.description[0].upper() + c.description[1:])
                               for name, c in MODELS.items()],
                        description="What makes the BRDF from the photo")
    refine: BoolProperty(name="Refine to Photo", default=True,
                         description="Refine the network's BRDF so that, rendered under the input "
                                     "lighting, it reproduces the photo")
    photo: PointerProperty(type=SpecGenPhotoSettings, name="Photo",
                           description="The photo's encoding, its sphere and its lighting")
    export_table: BoolProperty(name="Export Table", default=True,
                               description="Also write the BRDF as a compact material file (<name>.npz, "
                               "a few MB) beside the lookups; lookups that go missing are baked again "
                               "from it when the .blend is opened")
    material: PointerProperty(name="Material", type=bpy.types.Material, poll=_is_specgen_material,
                              description="SpecGen material that Apply assigns (each Generate "
                              "makes a new one unless Replace Materials is on)")
    refine_residual: FloatProperty(name="Refined Photo Match", default=-1.0, precision=4,
                                   description="Self-reproduction of the last refined table: PSNR (dB) of "
                                   "its render under the photo's lighting against the photo (negative: "
                                   "not refined)")
    # State written by the operators (not shown as settings).
    refine_summary: StringProperty(name="Refinement", default="", options={"HIDDEN"})
    atlas_json: StringProperty(name="Baked Lookup", default="", options={"HIDDEN"})
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype="FACTOR",
                            options={"HIDDEN"})
    running: StringProperty(name="Running", default="", options={"HIDDEN"})


def output_dir(settings: SpecGenSettings) -> str:
    """The output folder as an absolute path (a temp folder if the .blend is unsaved and the
    setting is relative)."""
    raw = settings.output_dir or "//specgen/"
    if raw.startswith("//") and not bpy.data.filepath:
        return os.path.join(tempfile.gettempdir(), "specgen", raw[2:])
    return bpy.path.abspath(raw)


CLASSES = (*PHOTO_CLASSES, SpecGenSettings)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.specgen = PointerProperty(type=SpecGenSettings)


def unregister() -> None:
    del bpy.types.Scene.specgen
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
