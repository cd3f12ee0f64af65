"""The panel's photo settings (``scene.specgen.photo``) as the core's objects, through the same
functions the command line uses: :class:`~specgen_addon.photo.sphere_image.PhotoSource` (encoding,
white level, circle, mask), :func:`~specgen_addon.photo.photo_lighting.parse_lighting` with
:class:`~specgen_addon.photo.photo_lighting.Light` (lights, ambient, panorama),
:func:`~specgen_addon.photo.light_estimate.estimated_lighting` and
:func:`~specgen_addon.photo.light_probe.lighting_from_probe`; "lit like this scene" reads the scene
in :mod:`.scene_lighting`.

What needs bpy is read on the main thread (:func:`lighting_job`); what takes time (the estimate,
the chrome ball, writing a panorama) runs in the returned job, on Generate's worker thread.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import bpy

from specgen_addon.common.errors import ImageInputError, SpecGenError
from specgen_addon.photo.light_estimate import estimated_lighting
from specgen_addon.photo.light_probe import lighting_from_probe
from specgen_addon.photo.photo_lighting import NO_MAP, Light, parse_lighting
from specgen_addon.photo.sphere_image import PhotoSource
from specgen_addon.photo.white_balance import parse_patch

from . import naming

#: What a lighting job returns: the photo's lighting and the lines the run reports about it.
LightingJob = Callable[[object], tuple[object, list[str]]]


def _file(path: str, what: str) -> Path:
    """A path setting (``//`` relative to the .blend) as an existing file, else one sentence."""
    if not path.strip():
        raise SpecGenError(f"choose {what} first")
    full = Path(bpy.path.abspath(path))
    if not full.is_file():
        raise SpecGenError(f"{full}: {what} not found")
    return full


def _circle(circle, what: str):
    """``(circle, mask)`` of a circle setting (:class:`.photo_properties.SpecGenCircle`): found
    (None, None), given, or from a mask file."""
    if circle.mode == "CIRCLE":
        if not circle.radius > 0:
            raise ImageInputError(f"the {what}'s circle needs a radius above 0 pixels")
        return (float(circle.x), float(circle.y), float(circle.radius)), None
    if circle.mode == "MASK":
        return None, _file(circle.mask, f"the {what}'s mask file")
    return None, None


def photo_source(photo, image):
    """The photo as Generate hands it to the core: a :class:`PhotoSource` of a file with the
    panel's encoding, white level and circle, or the pixels of an image not saved to a file."""
    circle, mask = _circle(photo.sphere, "sphere")
    if not isinstance(image, (str, os.PathLike)):
        custom = [name for name, used in (("a white level", photo.white_level > 0),
                                          ("the white patch", photo.use_white_patch),
                                          ("the sphere's circle or mask", photo.sphere.mode != "AUTO"),
                                          ("the circle preview", photo.circle_preview),
                                          ("the estimated lighting", photo.lighting == "ESTIMATE"),
                                          ("the chrome ball lighting", photo.lighting == "PROBE")) if used]
        if custom:
            raise SpecGenError(f"{custom[0]} needs the photo as a file: save the image first")
        return image
    patch = parse_patch(",".join(f"{v:g}" for v in photo.white_patch)) if photo.use_white_patch else None
    return PhotoSource(Path(image), encoding=photo.encoding, white_level=photo.white_level or None,
                       circle=circle, mask=mask, white_patch=patch)


def balances_to_the_light(photo) -> bool:
    """Whether the white patch is balanced to a white surface's colour under the given light (as
    the command line does); an estimated or chrome-ball light, photographed alike, keeps it neutral."""
    return bool(photo.use_white_patch) and photo.lighting not in ("ESTIMATE", "PROBE")


def balanced_to_the_light(source, lighting):
    """``source`` with its white patch balanced to a white surface's colour under ``lighting``
    (no bpy: runs on Generate's worker thread)."""
    if not isinstance(source, PhotoSource) or source.white_patch is None:
        return source
    return replace(source, white_target=tuple(float(v) for v in lighting.white_sphere_rgb()))


def panel_lights(photo) -> tuple[Light, ...]:
    """The light list as the core's lights (azimuth and elevation in the camera's frame)."""
    return tuple(Light.from_angles(math.degrees(li.azimuth), math.degrees(li.elevation), li.power,
                                   li.colour.strip() or "D65") for li in photo.lights)


def lighting_job(photo, scene, out_dir: str, stem: str, overwrite: bool, target=None) -> LightingJob:
    """Check the lighting settings now (one sentence when wrong) and return the job that makes
    the photo's lighting from the photo source. ``target`` is the ball's world position for the
    scene's point lights (default: the world origin)."""
    kind = photo.lighting
    if kind == "CANONICAL":
        lighting = parse_lighting(None)
        return lambda source: (lighting, [])
    if kind == "LIGHTS":
        lighting = parse_lighting(NO_MAP, lights=panel_lights(photo), ambient=photo.ambient)
        return lambda source: (lighting, [])
    if kind == "PANORAMA":
        from_file = photo.input_env == "FILE"
        env = str(_file(photo.input_env_file, "a panorama file")) if from_file else photo.input_env
        # Calibrated is drawn (and means something) for a file only: a tick left from a file is
        # not held against a bundled map the user picked afterwards
        lighting = parse_lighting(env, photo.input_rotation, photo.input_exposure, photo.input_key_light,
                                  lights=panel_lights(photo), ambient=photo.ambient,
                                  calibrated=photo.calibrated and from_file)
        return lambda source: (lighting, [])
    if kind == "ESTIMATE":
        def estimate(source):
            lighting, text = estimated_lighting(source)
            return lighting, [f"lighting {text}"]
        return estimate
    if kind == "PROBE":
        probe = _file(photo.probe_path, "a chrome ball photo")
        circle, mask = _circle(photo.probe_ball, "chrome ball")
        env_path = naming.probe_exr(out_dir, stem)
        reflectance = float(photo.probe_reflectance)

        def unwrap(source):
            lighting, notes = lighting_from_probe(probe, source, env_path, circle=circle, mask=mask,
                                                  reflectance=reflectance, overwrite=overwrite)
            return lighting, [f"chrome ball: {n}" for n in notes] + [
                f"{env_path.name}: the room's environment unwrapped from the chrome ball (camera frame)"]
        return unwrap
    if kind == "SCENE":
        from .scene_lighting import read_scene_lighting

        taken = read_scene_lighting(scene, target)
        env_path = naming.scene_env_exr(out_dir, stem)

        def from_scene(source):
            lighting = taken.lighting(env_path, overwrite=True)
            warning = taken.warning()
            return lighting, taken.notes + ([f"warning: {warning}"] if warning else [])
        return from_scene
    raise SpecGenError(f"unknown lighting source {kind!r}")
