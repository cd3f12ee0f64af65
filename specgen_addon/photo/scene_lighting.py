"""A 3D scene's lights and world as a photo's lighting ("lit like this scene"), without bpy.

Blender's Generate button can take the photo's lighting from the open scene: the world's
equirectangular Environment Texture (through its Mapping node, times the Background strength) and
the scene's sun lights and far point lights, all seen from the active camera. The Blender tier
reads those values; this module turns them into the photo's
:class:`~specgen_addon.photo.photo_lighting.InputLighting`:

* **Frames.** A photo's lighting lives in the camera's frame (x right, y up, z towards the camera),
  which is Blender's camera-local frame (a camera looks down its local −Z with +Y up). A world
  direction ``w`` is ``Rᵀ w`` there, ``R`` the camera's world rotation.
* **Suns.** A sun shines along its local −Z, so the direction towards it is its local +Z. Its
  strength is an irradiance in W·m⁻² (a white diffuse surface facing it has radiance ``S/π``), and
  a light of power 1 is an irradiance of π: power ``S/π``.
* **Point lights far away.** A point light of power ``P`` (W) at distance ``d`` gives an irradiance
  ``P / (4π d²)`` (Cycles' convention, checked against a render of a white plane), so it becomes a
  distant light from its direction with power ``P / (4π² d²)``. Spot lights are taken the same way
  when the ball lies inside their cone; the cone's soft edge is not modelled.
* **Colours.** A light's RGB colour becomes a light of the same luminance whose colour is white
  (D65) or the nearest black body (a colour temperature such as ``3200K``), since the photo's
  lights are spectra; a colour far from both is reported.
* **The world.** The panorama is resampled into the camera's frame (:func:`world_in_camera_frame`)
  and used calibrated: its values are radiance, times the Background strength. Blender's equirect
  convention is the renderer's (:mod:`specgen_addon.render.environment`), whose frame maps to
  Blender's as ``(x, y, z) → (x, −z, y)``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from specgen_addon.common.image_io import write_exr
from specgen_addon.photo.photo_lighting import Light, LightingError, parse_lighting
from specgen_addon.render.environment import (
    _bilinear_equirect,
    _box_downsample,
    _texel_directions,
    srgb_luminance_weights,
)

#: Width of the camera-frame panorama written for the photo's lighting (as the renderer's maps).
PANORAMA_WIDTH = 512
#: A colour whose chromaticity lies this far (largest relative channel difference after matching
#: luminance) from the nearest white or black body is reported as changed.
COLOUR_TOLERANCE = 0.05
#: Black-body temperatures searched for a light's colour (K), geometric steps of about 1 %.
_KELVIN_GRID = np.geomspace(1000.0, 40000.0, 371)


def rotation_part(matrix) -> np.ndarray:
    """The rotation (3, 3) of a 3×3 or 4×4 world matrix, its columns normalised (scale removed)."""
    m = np.asarray(matrix, np.float64)[:3, :3]
    norms = np.linalg.norm(m, axis=0)
    if m.shape != (3, 3) or not np.all(norms > 0) or not np.all(np.isfinite(m)):
        raise LightingError("an object's world matrix has no rotation (a zero scale)")
    return m / norms


def to_camera_frame(camera_rotation: np.ndarray, world_direction) -> np.ndarray:
    """A world direction (3,) in the camera's frame (x right, y up, z towards the camera), unit."""
    d = np.asarray(camera_rotation, np.float64).T @ np.asarray(world_direction, np.float64)
    return d / np.linalg.norm(d)


def euler_xyz(rotation_rad) -> np.ndarray:
    """Blender's XYZ Euler rotation (radians) as a matrix: ``Rz · Ry · Rx``."""
    x, y, z = (float(a) for a in rotation_rad)
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def mapping_matrix(kind: str, rotation_rad=(0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    """The linear part (3, 3) of Blender's Mapping node on a direction: ``POINT`` and ``VECTOR``
    rotate after scaling (``R S``), ``TEXTURE`` is the inverse (``S⁻¹ Rᵀ``), ``NORMAL`` ``R S⁻¹``."""
    r = euler_xyz(rotation_rad)
    s = np.asarray(scale, np.float64)
    if np.any(s == 0) or not np.all(np.isfinite(s)):
        raise LightingError(f"the world's Mapping node has a zero scale {tuple(s)}")
    if kind in ("POINT", "VECTOR"):
        return r @ np.diag(s)
    if kind == "TEXTURE":
        return np.diag(1.0 / s) @ r.T
    if kind == "NORMAL":
        return r @ np.diag(1.0 / s)
    raise LightingError(f"unknown Mapping node type {kind!r}")


def world_in_camera_frame(rgb: np.ndarray, camera_rotation: np.ndarray,
                          texture_matrix: np.ndarray | None = None,
                          width: int = PANORAMA_WIDTH) -> np.ndarray:
    """A Blender world's equirect image (H, W, 3, row 0 on top, linear) resampled into the photo's
    camera frame at ``width`` × ``width/2`` (bilinear; the source box-averaged first, so a large map
    is not aliased). ``texture_matrix`` is the Mapping node's (:func:`mapping_matrix`): the world
    direction ``w`` reads the image at ``M w``."""
    src = np.maximum(np.asarray(rgb, np.float32)[..., :3], 0.0)
    if src.ndim != 3 or src.shape[0] < 2 or src.shape[1] < 2:
        raise LightingError(f"the world's image must be H×W×3, got shape {src.shape}")
    src = _box_downsample(src, 2 * width)
    cam = _texel_directions(width // 2, width, 0.0)                   # camera frame, renderer's
    world = cam @ np.asarray(camera_rotation, np.float64).T            # Blender world: R c
    tex = world @ (np.eye(3) if texture_matrix is None else np.asarray(texture_matrix, np.float64)).T
    tex /= np.maximum(np.linalg.norm(tex, axis=-1, keepdims=True), 1e-12)
    renderer = np.stack([tex[..., 0], tex[..., 2], -tex[..., 1]], -1)  # Blender → renderer frame
    return np.maximum(_bilinear_equirect(src, renderer, 0.0), 0.0).astype(np.float32)   # as the renderer clamps


def _blackbody_chromaticity(kelvin: float) -> np.ndarray:
    """(3,) linear-sRGB colour of a unit-luminance black body, as a light of that colour renders."""
    rgb = np.asarray(Light((0.0, 0.0, 1.0), 1.0, f"{kelvin:.0f}K").distant_light().rgb())
    return rgb / float(_luminance(rgb))


@functools.lru_cache(maxsize=1)
def _blackbody_chromaticities() -> np.ndarray:
    """:func:`_blackbody_chromaticity` at every temperature of :data:`_KELVIN_GRID`."""
    return np.array([_blackbody_chromaticity(k) for k in _KELVIN_GRID])


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, np.float64) @ srgb_luminance_weights()


@dataclass(frozen=True)
class LightColour:
    """A light's RGB colour as the photo's lights take it: a colour name (``D65`` or ``NNNNK``),
    the RGB colour's luminance (a factor on the light's power) and how far the chromaticity moved."""

    name: str
    luminance: float
    error: float

    @property
    def changed(self) -> bool:
        return self.error > COLOUR_TOLERANCE


def light_colour(rgb) -> LightColour:
    """The nearest of white (D65) and the black bodies 1000–40000 K to a linear-sRGB colour (3,),
    compared at equal luminance (largest relative channel difference)."""
    c = np.asarray(rgb, np.float64)[:3]
    y = float(_luminance(c))
    if not (np.all(np.isfinite(c)) and y > 0):
        raise LightingError(f"a light's colour {tuple(np.round(c, 3))} has no brightness")
    target = c / y
    white = np.ones(3)
    err_white = float(np.max(np.abs(target - white)))
    bodies = _blackbody_chromaticities()
    errs = np.max(np.abs(bodies - target[None]), axis=1)
    i = int(np.argmin(errs))
    if err_white <= errs[i] or err_white <= 0.01:
        return LightColour("D65", y, err_white)
    lo, hi = _KELVIN_GRID[max(i - 1, 0)], _KELVIN_GRID[min(i + 1, len(_KELVIN_GRID) - 1)]
    fine = np.unique(np.round(np.linspace(lo, hi, 41)))          # whole kelvins between the neighbours
    fine_errs = [float(np.max(np.abs(_blackbody_chromaticity(k) - target))) for k in fine]
    j = int(np.argmin(fine_errs))
    return LightColour(f"{fine[j]:.0f}K", y, fine_errs[j])


def emitted_rgb(color, exposure: float = 0.0, temperature_k: float | None = None) -> np.ndarray:
    """The linear RGB a light's settings multiply its power by: its colour, ``2^exposure`` and, when
    it uses a colour temperature, that black body's colour at unit luminance."""
    rgb = np.asarray(color, np.float64)[:3] * 2.0 ** float(exposure)
    if temperature_k is not None:
        body = Light((0.0, 0.0, 1.0), 1.0, f"{float(temperature_k):.0f}K").distant_light().rgb()
        rgb = rgb * np.asarray(body) / float(_luminance(np.asarray(body)))
    return rgb


def sun_light(camera_rotation: np.ndarray, sun_rotation: np.ndarray, strength_w_m2: float, rgb) -> Light:
    """A Blender sun (its world rotation, strength in W·m⁻², linear colour) as a photo's light."""
    colour = light_colour(rgb)
    towards = np.asarray(sun_rotation, np.float64)[:, 2]   # it shines along −Z: the light lies at +Z
    return Light(tuple(to_camera_frame(camera_rotation, towards)),
                 float(strength_w_m2) * colour.luminance / math.pi, colour.name)


def point_irradiance(power_w: float, distance: float) -> float:
    """Irradiance (W·m⁻²) of a point light of ``power_w`` at ``distance`` (Cycles: ``P / (4π d²)``)."""
    if not distance > 0:
        raise LightingError("a point light sits on the ball itself (distance 0)")
    return float(power_w) / (4.0 * math.pi * distance * distance)


def point_light(camera_rotation: np.ndarray, light_position, target, power_w: float, rgb) -> Light:
    """A Blender point light (world position, power in W, linear colour) seen from ``target`` (the
    ball's world position) as a distant light from its direction."""
    offset = np.asarray(light_position, np.float64) - np.asarray(target, np.float64)
    distance = float(np.linalg.norm(offset))
    colour = light_colour(rgb)
    power = point_irradiance(power_w, distance) * colour.luminance / math.pi
    return Light(tuple(to_camera_frame(camera_rotation, offset)), power, colour.name)


def inside_cone(spot_rotation: np.ndarray, light_position, target, spot_size_rad: float) -> bool:
    """Whether ``target`` lies inside a spot light's cone (full angle ``spot_size_rad``; the spot
    shines along its local −Z)."""
    axis = -np.asarray(spot_rotation, np.float64)[:, 2]
    offset = np.asarray(target, np.float64) - np.asarray(light_position, np.float64)
    n = float(np.linalg.norm(offset))
    return n > 0 and float(axis @ offset) / n >= math.cos(spot_size_rad / 2.0)


@dataclass
class SceneLighting:
    """What was taken from a scene: lights, a camera-frame panorama (radiance × strength, or None)
    and the names of what could not be taken, for the run's warning."""

    lights: list[Light] = field(default_factory=list)
    panorama: np.ndarray | None = None
    strength: float = 1.0
    not_taken: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def warning(self) -> str | None:
        """One sentence naming what the photo's lighting leaves out, or None."""
        if not self.not_taken:
            return None
        return "lit like this scene leaves out " + "; ".join(self.not_taken)

    def lighting(self, panorama_path: str | Path | None = None, overwrite: bool = True):
        """The :class:`~specgen_addon.photo.photo_lighting.InputLighting`: the panorama (if any)
        written to ``panorama_path`` (an EXR, used calibrated, ``strength`` as its exposure) and
        the lights. Refused in one sentence when the scene gives no light at all."""
        env = None
        panorama = self.panorama
        if panorama is not None and float(np.max(panorama)) * self.strength > 0:
            if panorama_path is None:
                raise LightingError("the world's panorama needs a file to be written to")

            write_exr(Path(panorama_path), {c: panorama[..., i] for i, c in enumerate("RGB")},
                      overwrite=overwrite)
            env = str(panorama_path)
        if env is None and not self.lights:
            left = f" ({'; '.join(self.not_taken)} not taken)" if self.not_taken else ""
            raise LightingError("the scene gives no light to take: add a sun, a point light or a "
                                f"world with an environment texture{left}")
        if env is None:
            return parse_lighting("none", lights=tuple(self.lights))
        return parse_lighting(env, exposure=float(self.strength), lights=tuple(self.lights), calibrated=True,
                              key_light=False)
