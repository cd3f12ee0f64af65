"""The collapsible "Photo" section of the SpecGen panel: encoding, white level, the sphere's
circle and the photo's lighting (with its list of lights), drawn from ``scene.specgen.photo``."""

from __future__ import annotations

import bpy


class SPECGEN_UL_lights(bpy.types.UIList):
    """The room's lights, one row each: azimuth, elevation, power, colour."""

    bl_idname = "SPECGEN_UL_lights"

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index=0):
        row = layout.row(align=True)
        row.prop(item, "azimuth", text="Az")
        row.prop(item, "elevation", text="El")
        row.prop(item, "power", text="×")
        row.prop(item, "colour", text="")


class SPECGEN_OT_light_add(bpy.types.Operator):
    """Add a distant light of the room (direction in the camera's frame, power, colour)"""

    bl_idname = "specgen.light_add"
    bl_label = "Add Light"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        photo = context.scene.specgen.photo
        photo.lights.add()
        photo.active_light = len(photo.lights) - 1
        return {"FINISHED"}


class SPECGEN_OT_light_remove(bpy.types.Operator):
    """Remove the selected light"""

    bl_idname = "specgen.light_remove"
    bl_label = "Remove Light"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return len(context.scene.specgen.photo.lights) > 0

    def execute(self, context):
        photo = context.scene.specgen.photo
        photo.lights.remove(min(photo.active_light, len(photo.lights) - 1))
        photo.active_light = max(0, min(photo.active_light, len(photo.lights) - 1))
        return {"FINISHED"}


def _draw_circle(col, circle, text: str, target: str) -> None:
    col.prop(circle, "mode", text=text)
    if circle.mode == "CIRCLE":
        sub = col.column(align=True)
        sub.prop(circle, "x")
        sub.prop(circle, "y")
        sub.prop(circle, "radius")
        sub.operator("specgen.pick_circle", icon="EYEDROPPER").target = target
    elif circle.mode == "MASK":
        col.prop(circle, "mask")


def draw_photo(layout, photo) -> None:
    """The Photo section, collapsible (closed until opened) where Blender has layout panels."""
    if hasattr(layout, "panel"):
        header, body = layout.panel("specgen_photo", default_closed=True)
        header.label(text="Photo")
        if body is None:
            return
    else:
        body = layout.column(heading="Photo")
    col = body.column()
    col.prop(photo, "encoding")
    col.prop(photo, "white_level")
    col.prop(photo, "use_white_patch")
    if photo.use_white_patch:
        col.prop(photo, "white_patch")
        col.operator("specgen.pick_circle", icon="EYEDROPPER").target = "PATCH"
    _draw_circle(col, photo.sphere, "Sphere", "SPHERE")
    col.prop(photo, "circle_preview")

    col = body.column()
    col.prop(photo, "lighting")
    kind = photo.lighting
    if kind == "PANORAMA":
        col.prop(photo, "input_env")
        if photo.input_env == "FILE":
            col.prop(photo, "input_env_file")
            col.prop(photo, "calibrated")
        col.prop(photo, "input_rotation")
        col.prop(photo, "input_exposure")
        col.prop(photo, "input_key_light")
    elif kind == "PROBE":
        col.prop(photo, "probe_path")
        _draw_circle(col, photo.probe_ball, "Ball", "PROBE")
        col.prop(photo, "probe_reflectance")
    elif kind == "ESTIMATE":
        col.label(text="Lights and ambient found from the ball's shading", icon="INFO")
    elif kind == "SCENE":
        col.label(text="The world and the sun/point lights, seen from the camera", icon="INFO")
    if kind in ("LIGHTS", "PANORAMA"):
        row = body.row()
        row.template_list("SPECGEN_UL_lights", "", photo, "lights", photo, "active_light", rows=2)
        ops = row.column(align=True)
        ops.operator("specgen.light_add", icon="ADD", text="")
        ops.operator("specgen.light_remove", icon="REMOVE", text="")
        body.prop(photo, "ambient")
    for line in photo.report.splitlines():
        body.label(text=line, icon="ERROR" if line.startswith("warning: ") else "LIGHT")


CLASSES = (SPECGEN_UL_lights, SPECGEN_OT_light_add, SPECGEN_OT_light_remove)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
