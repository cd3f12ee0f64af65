"""The lighting a sphere photo was taken under: a choice, not an assumption.

Three kinds (:class:`InputLighting`):

* ``canonical`` (default): the studio lighting every shipped input is rendered with
  (:mod:`specgen_addon.photo.sphere_image`: Blender's ``studio`` map plus a D65 key light);
* a **bundled** map: one of the CC0 HDRIs that ship with Blender (``forest``, ``courtyard`` ...),
  rotated about the up axis and scaled by an exposure;
* a **file**: the user's own equirectangular HDRI (``.exr`` or Radiance ``.hdr``).

To these, the room's own light as the user measured it (:class:`Light`): distant lights and a
sun by direction in the camera's frame (x right, y up, z towards the camera; or azimuth and
elevation: azimuth 0° faces the camera, +90° is to the right; elevation +90° is straight up),
power (1: as bright as the canonical key light, an irradiance of π) and colour (a CIE illuminant
or a colour temperature such as ``3200K``), several at once, plus a uniform ambient radiance. With
lights and no map (``env="none"``) they alone light the photo.

Maps are normalised to unit mean luminance before the exposure is applied, unless the user says
the panorama is calibrated (``calibrated``: its values are radiance as photographed, kept as they
are) (as the renderer does for
its own maps), and the photo is taken to be ``EXPOSURE × radiance`` like the canonical input, so an
exposure of 1 means "as bright as the canonical studio". The same object serves the network's input
preparation (:meth:`InputLighting.network_gain`: the photo is brought to the canonical lighting's
white level before the network sees it) and the refinement (:meth:`InputLighting.scene`: the
renderer scene whose linear map from BRDF table to pixels is fitted).
"""

from __future__ import annotations

import functools
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import ImageInputError, SpecGenError
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.photo.image_checks import ImageNote, check_image_header
from specgen_addon.render import DistantLight, Scene, sphere_geometry
from specgen_addon.render import environment_maps as lighting
from specgen_addon.render.environment import Environment
from specgen_addon.spectral import colour_tables

CANONICAL = "canonical"
#: No environment map: the given lights (and ambient) alone.
NO_MAP = "none"
HDRI_SUFFIXES = (".exr", ".hdr")
#: Exposure multipliers accepted (a factor of 2^±10 around the canonical level).
EXPOSURE_RANGE = (2.0 ** -10, 2.0 ** 10)
#: Largest light power accepted (1: the canonical key light): a million times the key light is far
#: beyond any room, and keeps the renders and fits clear of floating-point overflow.
MAX_LIGHT_POWER = 1e6
#: Largest ambient radiance accepted (1: a white surface facing the canonical key light), likewise.
MAX_AMBIENT = 1e6
#: Azimuth (degrees) a light given by angles may have: a turn either way.
AZIMUTH_RANGE = (-360.0, 360.0)
#: Elevation (degrees) a light given by angles may have: straight down to straight up.
ELEVATION_RANGE = (-90.0, 90.0)


class LightingError(SpecGenError):
    """An input lighting specification cannot be used (unknown map, unreadable file, bad value)."""


@dataclass(frozen=True)
class Light:
    """A distant light of the room: unit direction towards it in the camera's frame (x right, y up,
    z towards the camera), power (1 = the canonical key light's irradiance, π) and colour (a CIE
    illuminant name or a temperature such as ``"3200K"``)."""

    direction: tuple[float, float, float]
    power: float = 1.0
    colour: str = "D65"

    def __post_init__(self) -> None:
        d = np.asarray(self.direction, np.float64)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
            raise LightingError(f"a light needs a direction (a non-zero vector), got {self.direction}")
        if not (math.isfinite(self.power) and 0 < self.power <= MAX_LIGHT_POWER):
            raise LightingError(f"a light's power must be a positive number up to {MAX_LIGHT_POWER:,.0f} "
                                f"(1: the canonical key light), got {self.power:g}")

        try:
            colour_tables.illuminant(self.colour)
        except SpecGenError as exc:
            raise LightingError(f"light colour: {exc}") from None
        object.__setattr__(self, "direction", tuple(float(v) for v in d / np.linalg.norm(d)))

    @classmethod
    def from_angles(cls, azimuth_deg: float, elevation_deg: float, power: float = 1.0,
                    colour: str = "D65") -> Light:
        """A light by azimuth (0° faces the camera, +90° to the right) and elevation (+90° up), degrees."""
        az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
        return cls((math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)), power, colour)

    def distant_light(self):
        return DistantLight(self.direction, float(self.power * np.pi), self.colour)

    @property
    def label(self) -> str:
        x, y, z = self.direction
        az = round(math.degrees(math.atan2(x, z)))
        el = round(math.degrees(math.asin(max(-1.0, min(1.0, y)))))
        az = 180 if az == -180 else az   # straight behind is 180°, whichever way it rounds
        return f"light az {az}° el {el}° ×{self.power:g} {self.colour}"


def parse_light(text: str, vector: bool = False) -> Light:
    """``"AZ,EL[,POWER[,COLOUR]]"`` (degrees, azimuth in :data:`AZIMUTH_RANGE`, elevation in
    :data:`ELEVATION_RANGE`), or with ``vector`` ``"X,Y,Z[,POWER[,COLOUR]]"``, as a :class:`Light`;
    one clear sentence, quoting ``text``, for a light without a direction or one out of range."""
    parts = [p.strip() for p in str(text).split(",")]
    n = 3 if vector else 2
    what = "X,Y,Z" if vector else "AZIMUTH,ELEVATION (degrees)"
    try:
        values = [float(p) for p in parts[:n]]
    except ValueError:
        values = []
    if len(values) != n or len(parts) > n + 2 or (vector and not all(map(math.isfinite, values))):
        raise LightingError(f"a light needs a direction: {what}[,POWER[,COLOUR]], got {text!r}")
    if not vector:
        for name, value, (lo, hi) in (("azimuth", values[0], AZIMUTH_RANGE),
                                      ("elevation", values[1], ELEVATION_RANGE)):
            if not lo <= value <= hi:   # NaN too
                raise LightingError(f"a light's {name} must be a number of degrees in [{lo:g}, {hi:g}], "
                                    f"got {text!r}")
    try:
        power = float(parts[n]) if len(parts) > n and parts[n] else 1.0
    except ValueError:
        raise LightingError(f"a light's power must be a number, got {parts[n]!r} in {text!r}") from None
    colour = parts[n + 1] if len(parts) > n + 1 and parts[n + 1] else "D65"
    if vector:
        return Light(tuple(values), power, colour)  # type: ignore[arg-type]
    return Light.from_angles(values[0], values[1], power, colour)


@dataclass(frozen=True)
class InputLighting:
    """Lighting of the input photo.

    Parameters
    ----------
    env
        ``"canonical"``, the name of a bundled map, or a path to an ``.exr``/``.hdr`` file.
    rotation_deg
        Rotation of the map about the world up axis, degrees (ignored for ``canonical``).
    exposure
        Multiplier on the map's unit-mean-luminance radiance (ignored for ``canonical``).
    key_light
        Add the canonical D65 key light (always on for ``canonical``; off by default otherwise).
    lights
        The room's distant lights (:class:`Light`), besides the map (or alone, ``env="none"``).
    ambient
        Uniform ambient radiance added to the map (× the canonical key light's radiance, 1).
    calibrated
        The file map's values are radiance as photographed: no normalisation to unit mean.
    """

    env: str = CANONICAL
    rotation_deg: float = 0.0
    exposure: float = 1.0
    key_light: bool = False
    lights: tuple[Light, ...] = ()
    ambient: float = 0.0
    calibrated: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.env, str) or not self.env.strip():
            raise LightingError("input lighting needs a map name, a file, or 'canonical'")
        if not math.isfinite(self.rotation_deg):
            raise LightingError(f"input lighting rotation must be a finite angle, got {self.rotation_deg}")
        lo, hi = EXPOSURE_RANGE
        if not (math.isfinite(self.exposure) and lo <= self.exposure <= hi):
            raise LightingError(f"input lighting exposure must lie in [{lo:g}, {hi:g}], got {self.exposure}")
        if not (math.isfinite(self.ambient) and 0 <= self.ambient <= MAX_AMBIENT):
            raise LightingError(f"the ambient term must be a non-negative number up to {MAX_AMBIENT:,.0f} "
                                f"(1: a white surface facing the canonical key light), got {self.ambient:g}")
        if self.env == NO_MAP and not self.lights and self.ambient == 0 and not self.key_light:
            raise LightingError("with no map, give at least one light or an ambient term to light the photo")
        if (self.lights or self.ambient) and self.env == CANONICAL:
            raise LightingError("lights or an ambient term describe the room instead of the canonical "
                                "studio: give them with no map (none), or with a map")
        if self.calibrated and not self.is_file:
            raise LightingError("only a panorama file can be calibrated (its values taken as radiance)")

    # -- what kind ------------------------------------------------------------------------------
    @property
    def is_canonical(self) -> bool:
        return self.env == CANONICAL

    @property
    def is_file(self) -> bool:
        return Path(self.env).suffix.lower() in HDRI_SUFFIXES

    @property
    def has_map(self) -> bool:
        return self.env != NO_MAP

    @property
    def label(self) -> str:
        """Short description for reports, e.g. ``forest (rot 30°, ×1)``."""
        if self.is_canonical:
            return "canonical studio"
        parts = []
        if self.has_map:
            name = Path(self.env).name if self.is_file else self.env
            cal = ", calibrated" if self.calibrated else ""
            parts.append(f"{name} (rot {self.rotation_deg:g}°, ×{self.exposure:g}{cal})")
        if self.key_light:
            parts.append("key light")
        parts += [light.label for light in self.lights]
        if self.ambient:
            parts.append(f"ambient {self.ambient:g}")
        return " + ".join(parts)

    def validate(self) -> None:
        """Check the map exists and is readable, cheaply (before any expensive work)."""
        if self.is_canonical or not self.has_map:
            return
        if self.is_file:
            path = Path(self.env)
            if not path.is_file():
                raise LightingError(f"{path}: no such HDRI file")
            check_map_header(path)  # pixel limit and 2:1, from the header alone
            return

        if "/" in self.env or "\\" in self.env or ".." in self.env:
            raise LightingError(f"{self.env!r} is neither a bundled map name nor an .exr/.hdr file")
        names = lighting.available_envs()
        if self.env not in names:
            raise LightingError(f"no bundled map named {self.env!r}; available: {', '.join(names)}")

    # -- renderer objects -----------------------------------------------------------------------
    def environment(self):
        """The :class:`~specgen_addon.render.Environment` (unit mean luminance × exposure, rotated)."""
        if self.is_canonical:
            return lighting.load_environment(input_image.CANONICAL_ENV)
        rot = math.radians(self.rotation_deg)
        if not self.has_map:
            env = None
        elif self.is_file:
            path = str(Path(self.env).resolve())
            env = _file_environment(path, float(self.exposure), rot, self.calibrated, file_stamp(path))
        else:
            self.validate()
            env = lighting.load_environment(self.env, exposure=self.exposure, rotation_rad=rot)
        if self.ambient > 0:
            if env is None:
                return Environment.uniform((self.ambient,) * 3)
            return Environment(env.rgb + np.float32(self.ambient), env.rotation_rad, env.uplift, env.name)
        return env

    def scene(self, size: int | None = None):
        """Prepared renderer scene of the input photo (canonical sphere geometry), cached."""
        size = int(size or input_image.CANONICAL_SIZE)
        if self.is_canonical:
            return input_image._scene(input_image.CANONICAL_ENV, 0.0, size)
        return _scene(self, size, self._stamp())

    @property
    def image_exposure(self) -> float:
        """Photo value per unit radiance (the canonical input's :data:`EXPOSURE`)."""
        return input_image.EXPOSURE

    def white_sphere_rgb(self, size: int | None = None) -> np.ndarray:
        """Mean linear-sRGB photo value of a white Lambertian sphere under this lighting (3,)."""
        return _white_rgb(self, int(size or 0), self._stamp())

    def network_gain(self) -> np.ndarray:
        """Per-channel gain (3,) that maps a photo under this lighting to the canonical white level.

        A von Kries-style correction: the network was trained mostly on canonical inputs, so a photo
        under a brighter or coloured map is brought to where a canonical photo of the same material
        would be, before the network sees it. The refinement then fits the true lighting.
        """
        if self.is_canonical:
            return np.ones(3)
        return _white_rgb(InputLighting(), 0) / np.maximum(_white_rgb(self, 0, self._stamp()), 1e-12)

    def _stamp(self) -> tuple[int, int, int] | None:
        """The map file's identity now, so cached maps and scenes follow a file rewritten in place."""
        return file_stamp(self.env) if self.is_file else None


def parse_lighting(env: str | None, rotation_deg: float = 0.0, exposure: float = 1.0,
                   key_light: bool | None = None, lights: tuple[Light, ...] = (), ambient: float = 0.0,
                   calibrated: bool = False) -> InputLighting:
    """Build and validate an :class:`InputLighting` from CLI/panel values (``None`` → canonical;
    with lights or an ambient term and no map named, no map)."""
    env = CANONICAL if env in (None, "", CANONICAL) else str(env)
    if env == CANONICAL and (lights or ambient):
        env = NO_MAP
    light = InputLighting(env, float(rotation_deg), float(exposure),
                          bool(key_light) if key_light is not None else env == CANONICAL,
                          tuple(lights), float(ambient), bool(calibrated))
    light.validate()
    return light


#: Width a user's map is box-averaged down to while it is read (as the renderer's own maps).
MAP_WORK_WIDTH = 512


def check_map_header(path: str | Path) -> tuple[int, int] | None:
    """Refuse a panorama from its header alone, before any pixel is read: over the photo pixel
    limit (the same limit and message as photos), empty, or not exactly 2:1 (equirectangular)."""
    try:
        size = check_image_header(path)
    except ImageInputError as exc:
        raise LightingError(str(exc)) from None
    if size is None:
        return None
    w, h = size
    if w != 2 * h:
        raise LightingError(f"{path}: a panorama must be equirectangular, twice as wide as it is "
                            f"high; this one is {w}×{h}")
    return w, h


def read_map_bounded(path: str | Path, max_width: int = MAP_WORK_WIDTH) -> np.ndarray | None:
    """(H, W, 3) float32 linear RGB of an equirect map, read a strip of rows at a time and
    box-averaged by the power of two that brings it to ``max_width`` (what the renderer's
    halving does; a size it cannot halve far enough, one box of ``ceil(width / max_width)``
    texels), so a 100-megapixel map never exists in memory at full size, nor reaches the
    renderer at more than ``max_width``. NaN/Inf texels are
    refused and negative ones reported (they are clamped to 0), each with its count, as for
    photos. None when OpenImageIO is not importable (the renderer's reader is used instead)."""
    import warnings

    try:
        import OpenImageIO as oiio
    except ImportError:
        return None

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise LightingError(f"{path}: not a readable HDRI ({oiio.geterror().strip() or 'unreadable'})")
    try:
        spec = inp.spec()
        w, h, names = spec.width, spec.height, list(spec.channelnames)
        if all(c in names for c in "RGB"):
            idx = [names.index(c) for c in "RGB"]
        elif spec.nchannels >= 3:
            idx = [0, 1, 2]
        else:
            raise LightingError(f"{path}: environment map has no R, G, B channels (has {names})")
        f = 1
        while w // f > max_width and (h // f) % 2 == 0 and (w // f) % 2 == 0:
            f *= 2
        if w // f > max_width:  # a size halving cannot bring down (odd): one coarser box, so the
            f = math.ceil(w / max_width)  # renderer never gets a map of millions of texels
        out = np.empty((h // f, w // f, 3), np.float32)
        tile = spec.tile_height if spec.tile_width > 0 else 0
        step = math.lcm(f, tile) if tile else f  # whole tiles (scanline reads crash on tiled files)
        rows = max(step, ((1 << 21) // max(w, 1)) // step * step)  # about 2 M texels per strip
        negative = bad = 0
        for y in range(0, h, rows):
            y1 = min(y + rows, h)
            px = (inp.read_tiles(0, 0, 0, w, y, y1, 0, 1, 0, spec.nchannels, oiio.FLOAT) if tile else
                  inp.read_scanlines(0, 0, y, y1, 0, 0, spec.nchannels, oiio.FLOAT))
            if px is None:
                raise LightingError(f"{path}: not a readable HDRI ({oiio.geterror().strip() or 'truncated'})")
            rgb = np.asarray(px, np.float32).reshape(-1, w, spec.nchannels)[:, :w // f * f, idx]
            bad += int(rgb.size - np.isfinite(rgb).sum())
            negative += int((rgb < 0).sum())
            n = rgb.shape[0] // f
            out[y // f:y // f + n] = rgb[:n * f].reshape(n, f, w // f, f, 3).mean(axis=(1, 3))
    finally:
        inp.close()
    if bad:
        raise LightingError(f"{path}: environment map holds {bad:,} NaN or infinite values "
                            f"(of {w * h * 3:,}); fix or re-export it")
    if negative:
        warnings.warn(f"{path}: {negative:,} negative values (of {w * h * 3:,}) clamped to 0",
                      ImageNote, stacklevel=2)
    return out


def file_stamp(path: str | Path) -> tuple[int, int, int] | None:
    """(inode, modification time in ns, size) of a file, None when it cannot be read: part of the
    cache keys of a panorama, so a long-running session (Blender) never renders a map that a
    later run wrote anew under the same name."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


@functools.lru_cache(maxsize=4)
def _file_environment(path: str, exposure: float, rotation_rad: float, calibrated: bool = False,
                      stamp: tuple | None = None):
    """A panorama file as the renderer's environment: unit mean luminance × exposure, or, when
    ``calibrated``, its values as radiance × exposure. Read in strips (:func:`read_map_bounded`)."""
    check_map_header(path)
    try:
        rgb = read_map_bounded(path)
        if rgb is None:
            return Environment.from_file(path, exposure=exposure, rotation_rad=rotation_rad,
                                         normalise=not calibrated)
        env = Environment(rgb, rotation_rad=rotation_rad, name=Path(path).stem)  # as from_file
        env.rgb = env.rgb * np.float32(exposure if calibrated else exposure / env.mean_luminance())
        return env
    except LightingError:
        raise
    except SpecGenError as exc:
        raise LightingError(f"{path}: {exc}") from None
    except (OSError, ValueError) as exc:
        raise LightingError(f"{path}: not a readable HDRI ({type(exc).__name__})") from None


@functools.lru_cache(maxsize=4)
def _scene(light: InputLighting, size: int, stamp: tuple | None = None):
    lights = ([input_image._key_light()] if light.key_light else []) + [li.distant_light() for li in light.lights]
    return Scene(sphere_geometry(size), lights, light.environment(), sampling=input_image.input_sampling())


@functools.lru_cache(maxsize=8)
def _white_rgb(light: InputLighting, size: int, stamp: tuple | None = None) -> np.ndarray:
    """Exact (noise-free) white-Lambertian photo mean: irradiance/π, not a sampled render."""
    geo = sphere_geometry(size or 32)
    n = geo.normals[geo.mask]
    env = light.environment()
    rgb = env.irradiance_rgb(n) / np.pi if env is not None else np.zeros((n.shape[0], 3))
    keys = ([input_image._key_light()] if light.key_light or light.is_canonical else []) + \
        [li.distant_light() for li in light.lights]
    for key in keys:
        rgb = rgb + np.maximum(n @ key.unit_direction(), 0.0)[:, None] * key.rgb()[None] / np.pi
    return rgb.mean(axis=0) * light.image_exposure


#: Options whose comma-separated value may begin with a minus sign: a light from the left, from
#: below or behind; a circle or white patch reaching past the photo's left edge.
SIGNED_OPTIONS = ("--light", "--light-vector", "--white-patch", "--circle", "--probe-circle")
_SIGNED_VALUE = re.compile(r"^-[0-9.]")


def attach_signed_values(argv: Sequence[str]) -> list[str]:
    """``argv`` with ``--light -30,20`` written ``--light=-30,20`` (and so every option of
    :data:`SIGNED_OPTIONS`): argparse reads a value that starts with a minus sign and is not one
    plain number as an option of its own, and would refuse it with its usage."""
    argv = list(argv)
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] in SIGNED_OPTIONS and i + 1 < len(argv) and _SIGNED_VALUE.match(argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out
