"""*Pick in Image Editor*: a ball's circle clicked on its outline, or a white patch clicked at two
opposite corners, in the photo an Image Editor shows.

Glue only: the clicks become the photo's pixels, and the circle through them or the patch they span,
in :mod:`specgen_addon.photo.circle_pick`; the result is the panel's Centre and Radius (the command
line's ``--circle``) for the photo's ball or the chrome ball's, or its White Patch (``--white-patch``).
"""

from __future__ import annotations

import math
import os

import bpy
from bpy.props import EnumProperty

from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo.circle_pick import (
    MIN_PATCH_POINTS,
    MIN_POINTS,
    circle_through,
    patch_through,
    pixel_from_view,
    view_from_pixel,
)

TARGETS = (("SPHERE", "Sphere", "The ball in the photo"),
           ("PROBE", "Chrome Ball", "The chrome ball in its photo"),
           ("PATCH", "White Patch", "A neutral patch of the photo (a grey card, a white wall)"))
#: Mouse and key events the Image Editor keeps while points are picked (pan and zoom the photo).
_NAVIGATION = {"MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "TRACKPADPAN", "TRACKPADZOOM",
               "NDOF_MOTION", "NUMPAD_PLUS", "NUMPAD_MINUS", "MOUSEMOVE", "INBETWEEN_MOUSEMOVE"}


def circle_settings(photo, target: str):
    """The panel's circle setting the picked circle goes to."""
    return photo.sphere if target == "SPHERE" else photo.probe_ball


def set_picked_circle(circle, points) -> tuple[float, float, float]:
    """Fit the circle through ``points`` (the photo's pixels) and make it the setting's Centre and
    Radius; gives (cx, cy, r). Too few or collinear points: one sentence, the setting unchanged."""
    cx, cy, r = circle_through(points)
    circle.mode, circle.x, circle.y, circle.radius = "CIRCLE", cx, cy, r
    return cx, cy, r


def set_picked_patch(photo, points) -> tuple[int, int, int, int]:
    """The white patch spanning ``points`` (the photo's pixels) made the panel's White Patch, and
    turned on; gives (x, y, w, h). Too small: one sentence, the setting unchanged."""
    patch = patch_through(points)
    photo.white_patch, photo.use_white_patch = patch, True
    return patch


def _photo_path(settings, target: str) -> str:
    """The file the circle belongs to ('' when none is chosen)."""
    if target == "PROBE":
        path = settings.photo.probe_path
    elif settings.image is not None:
        path = settings.image.filepath
    else:
        path = settings.image_path
    return os.path.normpath(bpy.path.abspath(path)) if path.strip() else ""


def _shows(space, settings, target: str, path: str) -> bool:
    img = space.image
    if img is None:
        return False
    if target != "PROBE" and settings.image is not None:
        return img == settings.image
    return bool(img.filepath) and os.path.normpath(bpy.path.abspath(img.filepath)) == path


def _image_editor(context, settings, target: str):
    """(area, its main region) of an Image Editor showing the photo; an Image Editor showing
    something else is given the photo; None without an Image Editor."""
    path = _photo_path(settings, target)
    if not path and not (target != "PROBE" and settings.image is not None):
        raise SpecGenError("choose the chrome ball photo first" if target == "PROBE"
                           else "choose the input image first")
    screens = [w.screen for w in context.window_manager.windows] if context.window_manager else []
    areas = [a for s in screens for a in s.areas if a.type == "IMAGE_EDITOR"]
    area = next((a for a in areas if _shows(a.spaces.active, settings, target, path)), None)
    if area is None and areas:
        area = areas[0]
        if target != "PROBE" and settings.image is not None:
            area.spaces.active.image = settings.image
        else:
            if not os.path.isfile(path):
                raise SpecGenError(f"{path}: photo not found")
            area.spaces.active.image = bpy.data.images.load(path, check_existing=True)
    if area is None:
        return None
    region = next(r for r in area.regions if r.type == "WINDOW")
    return area, region


class SPECGEN_OT_pick_circle(bpy.types.Operator):
    """Click points on the ball's outline in the Image Editor (three or more; for a white patch, two opposite corners), then Enter"""

    bl_idname = "specgen.pick_circle"
    bl_label = "Pick in Image Editor"
    bl_options = {"REGISTER", "UNDO"}

    target: EnumProperty(name="Ball", items=TARGETS, default="SPHERE")

    def execute(self, context):
        # run without the mouse (a script, a headless Blender): there is nothing to click on
        self.report({"ERROR"}, "SpecGen: the circle is picked with the mouse in an Image Editor; "
                               "without one, type its Centre and Radius")
        return {"CANCELLED"}

    def invoke(self, context, event):
        settings = context.scene.specgen
        try:
            found = _image_editor(context, settings, self.target)
        except SpecGenError as exc:
            self.report({"ERROR"}, f"SpecGen: {exc}")
            return {"CANCELLED"}
        if found is None:
            self.report({"ERROR"}, "SpecGen: open an Image Editor first: the circle is picked on the "
                                   "photo there")
            return {"CANCELLED"}
        self._area, self._region = found
        self._points: list[tuple[float, float]] = []
        self._image = self._area.spaces.active.image
        self._draw = bpy.types.SpaceImageEditor.draw_handler_add(self._draw_points, (), "WINDOW", "POST_PIXEL")
        context.window_manager.modal_handler_add(self)
        self._say()
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type in _NAVIGATION:
            return {"PASS_THROUGH"}
        if event.value != "PRESS":
            return {"RUNNING_MODAL"}
        if event.type in {"ESC", "RIGHTMOUSE"}:
            self._end()
            self.report({"INFO"}, "SpecGen: circle picking cancelled; the circle is as it was")
            return {"CANCELLED"}
        if event.type in {"BACK_SPACE", "DEL"} and self._points:
            self._points.pop()
        elif event.type == "LEFTMOUSE":
            r = self._region
            x, y = event.mouse_x - r.x, event.mouse_y - r.y
            if not (0 <= x < r.width and 0 <= y < r.height):
                return {"PASS_THROUGH"}     # outside the Image Editor: the rest of Blender's
            w, h = self._image.size
            u, v = r.view2d.region_to_view(x, y)
            self._points.append(pixel_from_view(u, v, w, h))
        elif event.type in {"RET", "NUMPAD_ENTER", "SPACE"} and len(self._points) >= self._needed:
            photo = context.scene.specgen.photo
            try:
                if self.target == "PATCH":
                    x, y, w, h = set_picked_patch(photo, self._points)
                    said = f"white patch set: {w}×{h} px at ({x}, {y})"
                else:
                    cx, cy, rad = set_picked_circle(circle_settings(photo, self.target), self._points)
                    what = "chrome ball" if self.target == "PROBE" else "sphere"
                    said = (f"{what} circle set from {len(self._points)} points: centre ({cx:.1f}, "
                            f"{cy:.1f}) px, radius {rad:.1f} px")
            except SpecGenError as exc:
                self.report({"WARNING"}, f"SpecGen: {exc}")
                return {"RUNNING_MODAL"}
            self._end()
            self.report({"INFO"}, f"SpecGen: {said}")
            return {"FINISHED"}
        self._say()
        return {"RUNNING_MODAL"}

    @property
    def _needed(self) -> int:
        return MIN_PATCH_POINTS if self.target == "PATCH" else MIN_POINTS

    def _shape(self):
        """("circle", (cx, cy, r)) or ("patch", (x, y, w, h)) of the points so far, or None."""
        if len(self._points) < self._needed:
            return None
        try:
            if self.target == "PATCH":
                return "patch", patch_through(self._points)
            return "circle", circle_through(self._points)
        except SpecGenError:
            return None

    def _say(self) -> None:
        n, shape = len(self._points), self._shape()
        where = "two opposite corners of a neutral patch" if self.target == "PATCH" else "the ball's outline"
        fit = ""
        if n >= self._needed:
            fit = "; these points fix no shape" if shape is None else (
                "; patch {2}×{3} px at ({0}, {1}), Enter to set it".format(*shape[1]) if shape[0] == "patch"
                else "; circle ({:.1f}, {:.1f}) r {:.1f} px, Enter to set it".format(*shape[1]))
        self._area.header_text_set(f"SpecGen: click points on {where} ({n} of at least {self._needed}"
                                   f"{fit}); Backspace removes the last, Esc cancels")
        self._area.tag_redraw()

    def _end(self) -> None:
        bpy.types.SpaceImageEditor.draw_handler_remove(self._draw, "WINDOW")
        self._area.header_text_set(None)
        self._area.tag_redraw()

    def _overlay_lines(self, at) -> list[tuple[float, float]]:
        """Line segments (pairs of region positions, ``at`` mapping the photo's pixels there) of
        the overlay: a cross at each point picked, and the circle through them or the patch they
        span once there are enough."""
        lines = []
        for x, y in self._points:
            px, py = at(x, y)
            lines += [(px - 6, py), (px + 6, py), (px, py - 6), (px, py + 6)]
        shape = self._shape()
        if shape is not None and shape[0] == "circle":
            cx, cy, r = shape[1]
            outline = [at(cx + r * math.cos(2 * math.pi * k / 96), cy + r * math.sin(2 * math.pi * k / 96))
                       for k in range(97)]
        elif shape is not None:
            x, y, w, h = shape[1]
            outline = [at(x, y), at(x + w, y), at(x + w, y + h), at(x, y + h), at(x, y)]
        else:
            outline = []
        return lines + [p for a, b in zip(outline, outline[1:]) for p in (a, b)]

    def _draw_points(self) -> None:
        """The points picked and the circle through them (or the patch they span), over the photo."""
        if bpy.context.area != self._area or not self._points:
            return
        import gpu
        from gpu_extras.batch import batch_for_shader

        w, h = self._image.size
        view2d = self._region.view2d

        def at(x: float, y: float) -> tuple[float, float]:
            return view2d.view_to_region(*view_from_pixel(x, y, w, h), clip=False)

        lines = self._overlay_lines(at)
        shader = gpu.shader.from_builtin("UNIFORM_COLOR")
        shader.uniform_float("color", (1.0, 0.16, 0.16, 1.0))   # the circle preview's red
        batch_for_shader(shader, "LINES", {"pos": lines}).draw(shader)


CLASSES = (SPECGEN_OT_pick_circle,)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
