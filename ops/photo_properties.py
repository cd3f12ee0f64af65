"""Settings of the photo (``scene.specgen.photo``): how it is encoded, where its sphere is, and the
light it was taken under. The same choices as the command line's photo options
(docs/cli.md), turned into the core's objects by :mod:`.photo_inputs`."""

from __future__ import annotations

import math

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from specgen_addon.photo.light_probe import CHROME_REFLECTANCE

# "//" = relative to the .blend (Blender 4.5+ asks path properties to opt in)
PATH = {"PATH_SUPPORTS_BLEND_RELATIVE"} if bpy.app.version >= (4, 5, 0) else set()

ENCODINGS = (
    ("auto", "sRGB", ("8/16-bit values are sRGB-encoded (EXR/HDR are always linear, camera RAW is "
     "developed linearly)")),
    ("linear", "Linear", "8/16-bit values are linear light (a linear export of a RAW, a scientific camera)"),
)

CIRCLES = (
    ("AUTO", "Find", "Find the sphere in the photo"),
    ("CIRCLE", "Centre and Radius", ("The sphere's centre and radius in the photo's pixels (x right, y "
     "down from the top-left corner)")),
    ("MASK", "Mask File", "A mask image of the photo's size, the sphere white (or opaque)"),
)

LIGHTING_SOURCES = (
    ("CANONICAL", "Canonical Studio", "The studio lighting the network's inputs are rendered with"),
    ("LIGHTS", "Lights", ("The room's distant lights (and sun) by direction, power and colour, plus an "
     "ambient term")),
    ("PROBE", "Chrome Ball Photo", ("A photo of a chrome (mirror) ball taken from the same place under "
     "the same light, unwrapped into the room's environment (Debevec 1998)")),
    ("PANORAMA", "Panorama", ("An equirectangular HDRI (a bundled one or your own file), optionally "
     "with the room's lights")),
    ("ESTIMATE", "Estimate", ("A few distant lights and an ambient term estimated from the ball's own "
     "shading")),
    ("SCENE", "Lit Like This Scene", ("The lighting of this scene as the active camera sees it: the "
     "world's environment texture and the sun and point lights")),
)


def _input_env_items(self, context):
    """Blender's bundled HDRIs (found at run time) and 'File…'."""
    try:
        from specgen_addon.render.environment_maps import available_envs

        names = available_envs()
    except Exception:  # noqa: BLE001 (no studio lights found: a file still works)
        names = []
    items = [(n, n.title(), f"Blender's bundled '{n}' HDRI") for n in names if n != "canonical"]
    items.append(("FILE", "File…", "Your own equirectangular HDRI (.exr or .hdr)"))
    _input_env_items.cache = items  # Blender needs the strings kept alive
    return items


class SpecGenLight(bpy.types.PropertyGroup):
    """One distant light of the room, in the camera's frame (as the command line's --light)."""

    azimuth: FloatProperty(name="Azimuth", subtype="ANGLE", default=0.0, min=-2 * math.pi, max=2 * math.pi,
                           description="0° faces the camera, +90° is to the right")
    elevation: FloatProperty(name="Elevation", subtype="ANGLE", default=math.radians(45.0),
                             min=-math.pi / 2, max=math.pi / 2, description="+90° is straight up")
    power: FloatProperty(name="Power", default=1.0, min=0.0, soft_max=100.0,
                         description="1: as bright as the canonical key light (an irradiance of π, "
                                     "a Blender sun of strength π)")
    colour: StringProperty(name="Colour", default="D65",
                           description="A CIE illuminant (D65, D50, A, F2 …) or a colour temperature "
                                       "such as 3200K")


class SpecGenCircle(bpy.types.PropertyGroup):
    """Where a ball is in its photo: found, a circle (as the command line's X,Y,R) or a mask file."""

    mode: EnumProperty(name="Circle", items=CIRCLES, default="AUTO", description="Where the ball is")
    x: FloatProperty(name="Centre X", default=0.0, min=0.0, description="Pixels from the left edge")
    y: FloatProperty(name="Centre Y", default=0.0, min=0.0, description="Pixels from the top edge")
    radius: FloatProperty(name="Radius", default=0.0, min=0.0, description="Radius in pixels")
    mask: StringProperty(name="Mask", subtype="FILE_PATH", options=PATH,
                         description="Mask image of the photo's size, the ball white (or opaque)")


class SpecGenPhotoSettings(bpy.types.PropertyGroup):
    """The photo's encoding, its sphere and its lighting."""

    encoding: EnumProperty(name="Encoding", items=ENCODINGS, default="auto",
                           description="How the photo's 8/16-bit values encode light")
    white_level: FloatProperty(name="White Level", default=0.0, min=0.0, soft_max=100.0,
                               description="Values at or above this count as saturated and are left "
                                           "out of every fit (EXR/HDR; 0: none; 8/16-bit files and "
                                           "RAW are checked at their own full scale)")
    use_white_patch: BoolProperty(name="White Patch", default=False,
                                  description="Balance the photo's white on a neutral patch or grey "
                                              "card in it (default: as shot)")
    white_patch: FloatVectorProperty(name="Patch", size=4, default=(0.0, 0.0, 16.0, 16.0), min=0.0,
                                     description="The patch's left, top, width and height in the "
                                                 "photo's pixels (y down from the top-left corner)")
    sphere: PointerProperty(type=SpecGenCircle, name="Sphere",
                            description="Where the sphere is in the photo")
    circle_preview: BoolProperty(name="Circle Preview", default=False,
                                 description="Write the photo with the circle used drawn on it "
                                             "(<name>_circle.png beside the lookups)")
    lighting: EnumProperty(name="Lighting", items=LIGHTING_SOURCES, default="CANONICAL",
                           description="The light the photo was taken under")
    lights: CollectionProperty(type=SpecGenLight, name="Lights")
    active_light: IntProperty(name="Active Light", default=0, min=0)
    ambient: FloatProperty(name="Ambient", default=0.0, min=0.0, soft_max=10.0,
                           description="Uniform ambient radiance of the room (1: the radiance of a "
                                       "white surface facing the canonical key light)")
    input_env: EnumProperty(name="Panorama", items=_input_env_items,
                            description="The panorama the photo was lit by")
    input_env_file: StringProperty(name="HDRI File", subtype="FILE_PATH", options=PATH,
                                   description="Equirectangular HDRI (.exr or .hdr) the photo was lit by")
    input_rotation: FloatProperty(name="Rotation", default=0.0, min=-360.0, max=360.0, precision=1,
                                  description="Rotation of the panorama about the up axis (degrees)")
    input_exposure: FloatProperty(name="Exposure", default=1.0, min=2.0 ** -10, max=2.0 ** 10,
                                  description="Brightness of the panorama relative to the canonical level "
                                              "(or, calibrated, a factor on its values)")
    input_key_light: BoolProperty(name="Key Light", default=False,
                                  description="Add the canonical D65 key light to the panorama")
    calibrated: BoolProperty(name="Calibrated", default=False,
                             description="The panorama file holds radiance as photographed: its values "
                                         "are used as they are (no normalisation to unit mean)")
    probe_path: StringProperty(name="Chrome Ball", subtype="FILE_PATH", options=PATH,
                               description="Photo of a chrome ball from the same place under the same "
                                           "light, taken like the photo")
    probe_ball: PointerProperty(type=SpecGenCircle, name="Chrome Ball Circle",
                                description="Where the chrome ball is in its photo")
    probe_reflectance: FloatProperty(name="Reflectance", default=CHROME_REFLECTANCE, min=0.05, max=1.0,
                                     description="The chrome ball's reflectance")
    report: StringProperty(name="Photo Report", default="", options={"HIDDEN"},
                           description="The lighting and the circle the last Generate used")


CLASSES = (SpecGenLight, SpecGenCircle, SpecGenPhotoSettings)
