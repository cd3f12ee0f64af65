"""*Pick in Image Editor*, headless with the bpy module: the points picked set the panel's Centre
and Radius (the command line's --circle) for the photo's ball or the chrome ball's; without an
Image Editor to pick in, one sentence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

from specgen_addon.common.errors import SpecGenError

circle_pick = addon_module("ops.circle_pick")
pytestmark = pytest.mark.blender


@pytest.fixture
def photo(registered_addon):
    return registered_addon.specgen.photo


@pytest.mark.parametrize("target", ["SPHERE", "PROBE"])
def test_points_on_the_outline_set_the_circles_centre_and_radius(photo, target):
    t = np.radians([20, 140, 260, 300])
    points = np.column_stack([245.7 + 108.2 * np.cos(t), 145.2 + 108.2 * np.sin(t)])
    circle = circle_pick.circle_settings(photo, target)
    got = circle_pick.set_picked_circle(circle, points)
    assert circle.mode == "CIRCLE"
    np.testing.assert_allclose((circle.x, circle.y, circle.radius), (245.7, 145.2, 108.2), rtol=1e-6)
    np.testing.assert_allclose(got, (245.7, 145.2, 108.2), rtol=1e-9)
    other = circle_pick.circle_settings(photo, "PROBE" if target == "SPHERE" else "SPHERE")
    assert other.mode == "AUTO"                                   # the other ball's setting untouched


def test_points_on_one_line_leave_the_circle_as_it_was(photo):
    with pytest.raises(SpecGenError, match="on one line"):
        circle_pick.set_picked_circle(photo.sphere, [(0, 0), (5, 5), (10, 10)])
    assert photo.sphere.mode == "AUTO" and photo.sphere.radius == 0.0


def test_the_photo_is_found_in_an_image_editor_or_put_there(photo, repo_dir):
    settings = bpy.context.scene.specgen
    with pytest.raises(SpecGenError, match="choose the input image first"):
        circle_pick._image_editor(bpy.context, settings, "SPHERE")
    with pytest.raises(SpecGenError, match="choose the chrome ball photo first"):
        circle_pick._image_editor(bpy.context, settings, "PROBE")
    settings.image_path = str(repo_dir / "examples" / "sphere.png")
    areas = bpy.context.window.screen.areas
    if not any(a.type == "IMAGE_EDITOR" for a in areas):
        assert circle_pick._image_editor(bpy.context, settings, "SPHERE") is None   # nowhere to pick
    area = areas[0]
    kind, area.type = area.type, "IMAGE_EDITOR"
    try:
        found_area, region = circle_pick._image_editor(bpy.context, settings, "SPHERE")
        assert found_area == area and region.type == "WINDOW"
        shown = area.spaces.active.image
        assert shown is not None and Path(bpy.path.abspath(shown.filepath)) == repo_dir / "examples" / "sphere.png"
        assert circle_pick._image_editor(bpy.context, settings, "SPHERE")[0] == area   # found, not loaded again
    finally:
        area.type = kind


def test_picking_without_the_mouse_is_refused_in_one_sentence(photo):
    with pytest.raises(RuntimeError, match="picked with the mouse in an Image Editor") as info:
        bpy.ops.specgen.pick_circle(target="SPHERE")
    assert len([line for line in str(info.value).splitlines() if line.strip()]) == 1


def test_two_corners_picked_set_and_turn_on_the_white_patch(photo):
    got = circle_pick.set_picked_patch(photo, [(140.6, 72.2), (120.3, 90.9)])
    assert got == (120, 72, 21, 19) and photo.use_white_patch
    assert tuple(photo.white_patch) == (120.0, 72.0, 21.0, 19.0)
    with pytest.raises(SpecGenError, match="under two pixels"):
        circle_pick.set_picked_patch(photo, [(5.0, 5.0), (5.5, 30.0)])
    assert tuple(photo.white_patch) == (120.0, 72.0, 21.0, 19.0)            # unchanged
