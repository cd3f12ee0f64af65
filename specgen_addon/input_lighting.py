"""The lighting a sphere photo was taken under: a choice, not an assumption.

Three kinds (:class:`InputLighting`):

* ``canonical`` (default): the studio lighting every shipped input is rendered with
  (:mod:`specgen_addon.input_image`: Blender's ``studio`` map plus a D65 key light);
* a **bundled** map: one of the CC0 HDRIs that ship with Blender (``forest``, ``courtyard`` ...),
  rotated about the up axis and scaled by an exposure;
* a **file**: the user's own equirectangular HDRI (``.exr`` or Radiance ``.hdr``).

Maps are normalised to unit mean luminance before the exposure is applied (as the renderer does for
its own maps), and the photo is taken to be ``EXPOSURE × radiance`` like the canonical input, so an
exposure of 1 means "as bright as the canonical studio". The same object serves the network's input
preparation (:meth:`InputLighting.network_gain`: the photo is brought to the canonical lighting's
white level before the network sees it) and the refinement (:meth:`InputLighting.scene`: the
renderer scene whose linear map from BRDF table to pixels is fitted).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import SpecGenError

CANONICAL = "canonical"
HDRI_SUFFIXES = (".exr", ".hdr")
#: Exposure multipliers accepted (a factor of 2^±10 around the canonical level).
EXPOSURE_RANGE = (2.0 ** -10, 2.0 ** 10)


class LightingError(SpecGenError):
    """An input lighting specification cannot be used (unknown map, unreadable file, bad value)."""


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
    """

    env: str = CANONICAL
    rotation_deg: float = 0.0
    exposure: float = 1.0
    key_light: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.env, str) or not self.env.strip():
            raise LightingError("input lighting needs a map name, a file, or 'canonical'")
        if not math.isfinite(self.rotation_deg):
            raise LightingError(f"input lighting rotation must be a finite angle, got {self.rotation_deg}")
        lo, hi = EXPOSURE_RANGE
        if not (math.isfinite(self.exposure) and lo <= self.exposure <= hi):
            raise LightingError(f"input lighting exposure must lie in [{lo:g}, {hi:g}], got {self.exposure}")

    # -- what kind ------------------------------------------------------------------------------
    @property
    def is_canonical(self) -> bool:
        return self.env == CANONICAL

    @property
    def is_file(self) -> bool:
        return Path(self.env).suffix.lower() in HDRI_SUFFIXES

    @property
    def label(self) -> str:
        """Short description for reports, e.g. ``forest (rot 30°, ×1)``."""
        if self.is_canonical:
            return "canonical studio"
        name = Path(self.env).name if self.is_file else self.env
        key = " + key light" if self.key_light else ""
        return f"{name} (rot {self.rotation_deg:g}°, ×{self.exposure:g}){key}"

    def validate(self) -> None:
        """Check the map exists and is readable, cheaply (before any expensive work)."""
        if self.is_canonical:
            return
        if self.is_file:
            path = Path(self.env)
            if not path.is_file():
                raise LightingError(f"{path}: no such HDRI file")
            check_map_header(path)
            return
        from . import lighting

        if "/" in self.env or "\\" in self.env or ".." in self.env:
            raise LightingError(f"{self.env!r} is neither a bundled map name nor an .exr/.hdr file")
        names = lighting.available_envs()
        if self.env not in names:
            raise LightingError(f"no bundled map named {self.env!r}; available: {', '.join(names)}")

    # -- renderer objects -----------------------------------------------------------------------
    def environment(self):
        """The :class:`~specgen_addon.render.Environment` (unit mean luminance × exposure, rotated)."""
        from . import input_image, lighting

        if self.is_canonical:
            return lighting.load_environment(input_image.CANONICAL_ENV)
        rot = math.radians(self.rotation_deg)
        if self.is_file:
            return _file_environment(str(Path(self.env).resolve()), float(self.exposure), rot)
        self.validate()
        return lighting.load_environment(self.env, exposure=self.exposure, rotation_rad=rot)

    def scene(self, size: int | None = None):
        """Prepared renderer scene of the input photo (canonical sphere geometry), cached."""
        from . import input_image

        size = int(size or input_image.CANONICAL_SIZE)
        if self.is_canonical:
            return input_image._scene(input_image.CANONICAL_ENV, 0.0, size)
        return _scene(self, size)

    @property
    def image_exposure(self) -> float:
        """Photo value per unit radiance (the canonical input's :data:`EXPOSURE`)."""
        from . import input_image

        return input_image.EXPOSURE

    def white_sphere_rgb(self, size: int | None = None) -> np.ndarray:
        """Mean linear-sRGB photo value of a white Lambertian sphere under this lighting (3,)."""
        return _white_rgb(self, int(size or 0))

    def network_gain(self) -> np.ndarray:
        """Per-channel gain (3,) that maps a photo under this lighting to the canonical white level.

        A von Kries-style correction: the network was trained mostly on canonical inputs, so a photo
        under a brighter or coloured map is brought to where a canonical photo of the same material
        would be, before the network sees it. The refinement then fits the true lighting.
        """
        if self.is_canonical:
            return np.ones(3)
        return _white_rgb(InputLighting(), 0) / np.maximum(_white_rgb(self, 0), 1e-12)


def parse_lighting(env: str | None, rotation_deg: float = 0.0, exposure: float = 1.0,
                   key_light: bool | None = None) -> InputLighting:
    """Build and validate an :class:`InputLighting` from CLI/panel values (``None`` → canonical)."""
    env = CANONICAL if env in (None, "", CANONICAL) else str(env)
    light = InputLighting(env, float(rotation_deg), float(exposure),
                          bool(key_light) if key_light is not None else env == CANONICAL)
    light.validate()
    return light


#: Accepted width / height of an equirectangular map: 2, within this relative tolerance.
MAP_ASPECT_TOLERANCE = 0.01
#: Width a user's map is box-averaged down to while it is read (as the renderer's own maps).
MAP_WORK_WIDTH = 512


def check_map_header(path: str | Path) -> tuple[int, int] | None:
    """Refuse an environment map from its header alone, before any pixel is read: over the photo
    pixel limit (the same limit and message as photos), empty, or not 2:1 (equirectangular)."""
    from .errors import ImageInputError
    from .image_checks import check_image_header

    try:
        size = check_image_header(path)
    except ImageInputError as exc:
        raise LightingError(str(exc)) from None
    if size is None:
        return None
    w, h = size
    if abs(w / h - 2.0) > 2.0 * MAP_ASPECT_TOLERANCE:
        raise LightingError(f"{path}: environment map is {w}×{h}; an equirectangular map is twice as "
                            "wide as it is tall (2:1)")
    return w, h


def read_map_bounded(path: str | Path, max_width: int = MAP_WORK_WIDTH) -> np.ndarray | None:
    """(H, W, 3) float32 linear RGB of an equirect map, read a strip of rows at a time and
    box-averaged by the power of two that brings it to ``max_width`` (what the renderer's
    halving does), so a 100-megapixel map never exists in memory at full size. NaN/Inf texels are
    refused and negative ones reported (they are clamped to 0), each with its count, as for
    photos. None when OpenImageIO is not importable (the renderer's reader is used instead)."""
    import warnings

    try:
        import OpenImageIO as oiio
    except ImportError:
        return None
    from .image_checks import ImageNote

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
        out = np.empty((h // f, w // f, 3), np.float32)
        rows = max(f, ((1 << 21) // max(w, 1)) // f * f)  # about 2 M texels per strip
        negative = bad = 0
        for y in range(0, h, rows):
            px = inp.read_scanlines(0, 0, y, min(y + rows, h), 0, 0, spec.nchannels, oiio.FLOAT)
            if px is None:
                raise LightingError(f"{path}: not a readable HDRI ({oiio.geterror().strip() or 'truncated'})")
            rgb = np.asarray(px, np.float32).reshape(-1, w, spec.nchannels)[..., idx]
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


@functools.lru_cache(maxsize=4)
def _file_environment(path: str, exposure: float, rotation_rad: float):
    from .render.environment import Environment

    check_map_header(path)
    try:
        rgb = read_map_bounded(path)
        if rgb is None:
            return Environment.from_file(path, exposure=exposure, rotation_rad=rotation_rad)
        env = Environment(rgb, rotation_rad=rotation_rad, name=Path(path).stem)  # as from_file
        env.rgb = env.rgb * np.float32(exposure / env.mean_luminance())
        return env
    except LightingError:
        raise
    except SpecGenError as exc:
        raise LightingError(f"{path}: {exc}") from None
    except (OSError, ValueError) as exc:
        raise LightingError(f"{path}: not a readable HDRI ({type(exc).__name__})") from None


@functools.lru_cache(maxsize=4)
def _scene(light: InputLighting, size: int):
    from . import input_image
    from .render import Scene, sphere_geometry

    lights = [input_image._key_light()] if light.key_light else []
    return Scene(sphere_geometry(size), lights, light.environment(), sampling=input_image.input_sampling())


@functools.lru_cache(maxsize=8)
def _white_rgb(light: InputLighting, size: int) -> np.ndarray:
    """Exact (noise-free) white-Lambertian photo mean: irradiance/π, not a sampled render."""
    from . import input_image
    from .render import sphere_geometry

    geo = sphere_geometry(size or 32)
    n = geo.normals[geo.mask]
    rgb = light.environment().irradiance_rgb(n) / np.pi
    if light.key_light or light.is_canonical:
        key = input_image._key_light()
        rgb = rgb + np.maximum(n @ key.unit_direction(), 0.0)[:, None] * key.rgb()[None] / np.pi
    return rgb.mean(axis=0) * light.image_exposure
