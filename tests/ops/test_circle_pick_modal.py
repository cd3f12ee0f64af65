"""*Pick in Image Editor*'s modal handler, driven by a sequence of events as Blender's window
would send them: clicks become the photo's pixels, Backspace removes one, Enter sets the circle or
patch (one report), Esc leaves the setting as it was, navigation and clicks outside the editor pass
through, and the overlay is drawn where the points and the circle are.

The bpy module has no window, so the operator's own methods run on a stand-in for its instance
with an Image Editor region whose view shows the whole photo; the drawing call itself (``gpu``)
needs a display and is not run.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

circle_pick = addon_module("ops.circle_pick")
Operator = circle_pick.SPECGEN_OT_pick_circle
pytestmark = pytest.mark.blender

PHOTO_W, PHOTO_H = 400, 300
#: The Image Editor's main region: 800×600 px at (10, 20) in the window, showing the whole photo.
REGION = dict(x=10, y=20, width=800, height=600)


class View2D:
    """The region's view: the photo fills the region (view 0–1 across it)."""

    def region_to_view(self, x, y):
        return x / REGION["width"], y / REGION["height"]

    def view_to_region(self, u, v, clip=False):
        return u * REGION["width"], v * REGION["height"]


class Area:
    def __init__(self):
        self.header = []

    def header_text_set(self, text):
        self.header.append(text)

    def tag_redraw(self):
        pass


class Picking:
    """The operator's methods on a stand-in for its instance, as `invoke` leaves it."""

    modal = Operator.modal
    _say, _end, _shape = Operator._say, Operator._end, Operator._shape
    _overlay_lines = Operator._overlay_lines
    _needed = Operator.__dict__["_needed"]

    def __init__(self, target):
        self.target = target
        self.reports = []
        self._points = []
        self._area = Area()
        self._region = SimpleNamespace(view2d=View2D(), **REGION)
        self._image = SimpleNamespace(size=(PHOTO_W, PHOTO_H))
        self._draw = bpy.types.SpaceImageEditor.draw_handler_add(lambda: None, (), "WINDOW", "POST_PIXEL")

    def report(self, kind, message):
        self.reports.append((next(iter(kind)), message))

    def send(self, type_, value="PRESS", at=None):
        """One event; ``at`` the photo's pixel (x right, y down) the mouse is over."""
        mx = my = 0
        if at is not None:
            mx = REGION["x"] + at[0] / PHOTO_W * REGION["width"]
            my = REGION["y"] + (1 - at[1] / PHOTO_H) * REGION["height"]
        return self.modal(bpy.context, SimpleNamespace(type=type_, value=value, mouse_x=mx, mouse_y=my))


@pytest.fixture
def photo(registered_addon):
    return registered_addon.specgen.photo


def on_circle(cx, cy, r, degrees):
    t = np.radians(degrees)
    return [(cx + r * np.cos(a), cy + r * np.sin(a)) for a in t]


def test_clicks_on_the_outline_then_enter_set_the_spheres_circle(photo):
    op = Picking("SPHERE")
    for point in on_circle(200.0, 140.0, 90.0, [10, 130, 250]):
        assert op.send("LEFTMOUSE", at=point) == {"RUNNING_MODAL"}
        assert op.send("LEFTMOUSE", value="RELEASE", at=point) == {"RUNNING_MODAL"}   # ignored
    assert len(op._points) == 3
    assert "circle (200.0, 140.0) r 90.0 px, Enter to set it" in op._area.header[-1]
    assert op.send("RET") == {"FINISHED"}
    sphere = photo.sphere
    assert sphere.mode == "CIRCLE"
    np.testing.assert_allclose((sphere.x, sphere.y, sphere.radius), (200.0, 140.0, 90.0), atol=1e-3)
    assert op.reports == [("INFO", "SpecGen: sphere circle set from 3 points: centre (200.0, 140.0) px, "
                                   "radius 90.0 px")]
    assert op._area.header[-1] is None                       # the header given back to Blender


def test_backspace_removes_the_last_point_and_enter_waits_for_three(photo):
    op = Picking("PROBE")
    good = on_circle(150.0, 150.0, 60.0, [0, 120, 240])
    op.send("LEFTMOUSE", at=good[0])
    op.send("LEFTMOUSE", at=good[1])
    op.send("LEFTMOUSE", at=(5.0, 5.0))                       # a slip of the hand
    op.send("BACK_SPACE")
    assert op.send("RET") == {"RUNNING_MODAL"}               # two points fix no circle yet
    assert "(2 of at least 3)" in op._area.header[-1]
    op.send("LEFTMOUSE", at=good[2])
    assert op.send("NUMPAD_ENTER") == {"FINISHED"}
    np.testing.assert_allclose((photo.probe_ball.x, photo.probe_ball.y, photo.probe_ball.radius),
                               (150.0, 150.0, 60.0), atol=1e-3)
    assert photo.sphere.mode == "AUTO"                       # the photo's own ball untouched


def test_escape_cancels_and_leaves_the_circle_as_it_was(photo):
    op = Picking("SPHERE")
    for point in on_circle(200.0, 140.0, 90.0, [10, 130, 250]):
        op.send("LEFTMOUSE", at=point)
    assert op.send("ESC") == {"CANCELLED"}
    assert photo.sphere.mode == "AUTO" and photo.sphere.radius == 0.0
    assert op.reports[-1][0] == "INFO" and "cancelled" in op.reports[-1][1]


def test_points_on_one_line_warn_and_keep_picking(photo):
    op = Picking("SPHERE")
    for point in [(10.0, 10.0), (50.0, 50.0), (90.0, 90.0)]:
        op.send("LEFTMOUSE", at=point)
    assert "these points fix no shape" in op._area.header[-1]
    assert op.send("RET") == {"RUNNING_MODAL"}
    assert op.reports[-1][0] == "WARNING" and "on one line" in op.reports[-1][1]
    assert photo.sphere.mode == "AUTO"


def test_navigation_and_clicks_outside_the_editor_pass_through(photo):
    op = Picking("SPHERE")
    for kind in ("MIDDLEMOUSE", "WHEELUPMOUSE", "MOUSEMOVE"):
        assert op.send(kind) == {"PASS_THROUGH"}
    outside = SimpleNamespace(type="LEFTMOUSE", value="PRESS", mouse_x=REGION["x"] - 3, mouse_y=REGION["y"] + 5)
    assert op.modal(bpy.context, outside) == {"PASS_THROUGH"}
    assert op._points == []


def test_two_corners_then_enter_set_the_white_patch(photo):
    op = Picking("PATCH")
    op.send("LEFTMOUSE", at=(140.6, 72.2))
    op.send("LEFTMOUSE", at=(120.3, 90.9))
    assert "patch 21×19 px at (120, 72)" in op._area.header[-1]
    assert op.send("SPACE") == {"FINISHED"}
    assert photo.use_white_patch and tuple(photo.white_patch) == (120.0, 72.0, 21.0, 19.0)
    assert op.reports[-1] == ("INFO", "SpecGen: white patch set: 21×19 px at (120, 72)")


def test_the_overlay_draws_a_cross_at_each_point_and_the_circle_through_them(photo):
    op = Picking("SPHERE")
    cx, cy, r = 200.0, 140.0, 90.0
    points = on_circle(cx, cy, r, [10, 130, 250])
    op.send("LEFTMOUSE", at=points[0])
    assert len(op._overlay_lines(lambda x, y: (x, y))) == 4  # one cross, no circle yet
    for point in points[1:]:
        op.send("LEFTMOUSE", at=point)
    lines = np.array(op._overlay_lines(lambda x, y: (x, y)))
    crosses, outline = lines[:12], lines[12:]
    np.testing.assert_allclose(crosses[::4] + [6, 0], np.array(points), atol=1e-6)   # each cross's centre
    assert len(outline) == 2 * 96
    np.testing.assert_allclose(np.hypot(outline[:, 0] - cx, outline[:, 1] - cy), r, atol=1e-3)
