"""The image SpecGen consumes: a sphere of the material, rendered canonically or loaded from a file.

Canonical input (:func:`render_input`), fixed so that every training and test image is comparable:

* geometry: unit sphere inscribed in a 128×128 frame, orthographic camera looking down −z
  (:func:`specgen_addon.render.sphere_geometry`); background 0;
* lighting: the ``studio`` environment map of the bpy wheel (unit mean luminance, rotation 0,
  Mallett 2019 uplifting) plus a D65 distant key light of irradiance π from the upper left front,
  direction ∝ (−1, 1, 1);
* spectral BRDFs are rendered at the default 21 bands (380–780 nm) and projected to linear sRGB
  through the CIE 1931 CMFs (white-balanced to D65); RGB-only BRDFs through ``eval_rgb``;
* exposure: radiance × :data:`EXPOSURE` (0.5, a white Lambertian peaks near 1); the linear EXR
  stores exactly that; the PNG is its sRGB encoding of the values clipped to [0, 1] (no other
  tone curve), 8 bits.

Training variants (:func:`render_training_input`) keep geometry and key light and change the
environment map (among :data:`specgen_addon.render.environment_maps.TRAIN_ENVS`), its rotation and the exposure.

User images (:func:`load_sphere_image`): read by :mod:`specgen_addon.photo.read` (EXR/HDR linear,
8/16-bit PNG/TIFF/JPEG sRGB-decoded or linear, camera RAW developed linearly; saturated pixels
marked), RGB or RGBA. The circle can be the user's (:class:`PhotoSource`: ``--circle``, ``--mask``).
Else the sphere is found from the alpha channel when there is one, else as a circle fitted (RANSAC)
to the outline of the foreground (pixels whose colour departs from the border's median colour by
more than a threshold; on an exactly black background, every non-zero pixel). The circle is then
refined to a fraction of a pixel from the outline's partly covered pixels
(:mod:`specgen_addon.photo.sphere_edge`). A camera photo (no black or single-colour background, or no
foreground outline that is a circle) is found from its lit outline instead
(:mod:`specgen_addon.photo.sphere_detect`). A sphere framed on whole pixels is cropped to its bounding
square and copied pixel for pixel; any other (off the grid, antialiased, another size) is
resampled bilinearly about the refined circle. Either way the background becomes 0.
:func:`crop_sphere` also says which of the two it did (:class:`SphereCrop`), and the pipeline gives
each kind its own shipped network.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.common.errors import ImageInputError, OutputExistsError, SpecGenError
from specgen_addon.common.image_io import write_png8
from specgen_addon.photo import ndimage_np
from specgen_addon.photo.colour_checker import checker_balance, find_checker
from specgen_addon.photo.ndimage_np import ransac_circle
from specgen_addon.photo.read import read_photo, stores_floats, warn_notes
from specgen_addon.photo.sphere_detect import find_ball, luminance
from specgen_addon.photo.sphere_edge import refine_circle
from specgen_addon.photo.white_balance import patch_gains
from specgen_addon.render import DistantLight, EnvSampling, Scene, sphere_geometry
from specgen_addon.render import environment_maps as lighting
from specgen_addon.render.geometry import pixel_grid
from specgen_addon.spectral import spectra

CANONICAL_SIZE = 128
EXPOSURE = 0.5
CANONICAL_ENV = "studio"
KEY_LIGHT_DIRECTION = (-1.0, 1.0, 1.0)
KEY_LIGHT_IRRADIANCE = float(np.pi)
#: Smallest sphere radius (pixels) accepted in a user image.
MIN_SPHERE_RADIUS_PX = 8


def input_sampling():
    """Environment sampling of input renders: 56 directions per pixel (half the evaluation's);
    the inputs are 128² RGB images and their noise is far below their quantisation."""
    return EnvSampling().scaled(0.5)


#: Seed and direction factor of an *independent* photo (:func:`independent_sampling`).
INDEPENDENT_SEED = 1
INDEPENDENT_SCALE = 2.0


def independent_sampling():
    """Environment sampling that shares no directions with :func:`input_sampling` (seed 1, twice the
    directions). A real photograph is lit by the whole map, not by the refinement operator's
    samples; a photo rendered with these stands in for one, so a fit to it cannot be exact by
    construction (no "inverse crime")."""
    return replace(input_sampling().scaled(INDEPENDENT_SCALE), seed=INDEPENDENT_SEED)


def with_independent_sampling(scene):
    """``scene`` (a prepared renderer scene) with :func:`independent_sampling` instead of its own."""
    return scene.with_sampling(independent_sampling())


def _key_light():
    return DistantLight(KEY_LIGHT_DIRECTION, KEY_LIGHT_IRRADIANCE, spectra.DEFAULT_ILLUMINANT)


@functools.lru_cache(maxsize=6)
def _scene(env_name: str, rotation_rad: float, size: int):
    """Prepared scenes are reused across materials (their samples do not depend on the BRDF)."""
    env = lighting.load_environment(env_name, rotation_rad=rotation_rad)
    return Scene(sphere_geometry(size), [_key_light()], env, sampling=input_sampling())


def _is_rgb_only(brdf) -> bool:
    return not hasattr(brdf, "eval") or getattr(brdf, "is_spectral", True) is False


def _render(brdf, env_name: str, rotation_rad: float, exposure: float, size: int,
            progress=None) -> np.ndarray:
    return photo_in_scene(brdf, _scene(env_name, float(rotation_rad), int(size)), exposure, progress)


def photo_in_scene(brdf, scene, exposure: float, progress=None) -> np.ndarray:
    """The photo of ``brdf`` in a prepared renderer scene: linear sRGB × ``exposure``, float32
    (spectral BRDFs at the default bands, RGB-only ones through ``eval_rgb``)."""
    if _is_rgb_only(brdf):
        rgb = scene.render_rgb(brdf, progress=progress).rgb
    else:
        rgb = scene.render_spectral(brdf, spectra.DEFAULT_WAVELENGTHS_NM, progress=progress).rgb
    rgb = np.clip(rgb, 0.0, None) * exposure  # negative values only from sRGB gamut clipping
    return rgb.astype(np.float32)


def render_input(brdf, size: int = CANONICAL_SIZE,
                 progress: Callable[[float], None] | None = None) -> np.ndarray:
    """Canonical input image of ``brdf``: linear sRGB (size, size, 3) float32 (module docstring)."""
    return _render(brdf, CANONICAL_ENV, 0.0, EXPOSURE, size, progress)


def render_independent_input(brdf, size: int = CANONICAL_SIZE,
                             progress: Callable[[float], None] | None = None) -> np.ndarray:
    """The canonical input image of ``brdf`` rendered with :func:`independent_sampling`: the same
    lighting, framing and exposure as :func:`render_input`, none of its environment samples."""
    scene = with_independent_sampling(_scene(CANONICAL_ENV, 0.0, int(size)))
    return photo_in_scene(brdf, scene, EXPOSURE, progress)


def training_variant(variant: int) -> tuple[str, float, float]:
    """(environment name, rotation in radians, exposure) of training lighting ``variant``.

    Variant 0 is the canonical lighting; others cycle through the training maps with a golden-angle
    rotation (8 distinct per map) and an exposure of 2^u, u ∈ [−0.5, 0.5] drawn from ``variant``.
    """
    if variant < 0:
        raise SpecGenError(f"training variant must be ≥ 0, got {variant}")
    if variant == 0:
        return CANONICAL_ENV, 0.0, EXPOSURE
    envs = lighting.TRAIN_ENVS
    name = envs[variant % len(envs)]
    rotation = float(np.mod((variant // len(envs)) % 8 * 2.399963229728653 + 0.7 * variant, 2 * np.pi))
    u = np.random.default_rng(variant).uniform(-0.5, 0.5)
    return name, round(rotation, 6), float(EXPOSURE * 2.0 ** u)


def render_training_input(brdf, variant: int, size: int = CANONICAL_SIZE) -> np.ndarray:
    """Input image of ``brdf`` under training lighting ``variant`` (0 = canonical), linear sRGB."""
    name, rotation, exposure = training_variant(variant)
    return _render(brdf, name, rotation, exposure, size)


# -- saving ---------------------------------------------------------------------------------------

def write_exr_rgb(path: str | Path, rgb: np.ndarray, overwrite: bool = False) -> None:
    """Write linear RGB (H, W, 3) as a float32 OpenEXR file, atomically."""
    import OpenEXR

    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_write(path, overwrite=overwrite) as tmp, OpenEXR.File(header, {"RGB": rgb}) as f:
        f.write(str(tmp))


def write_png_srgb(path: str | Path, rgb: np.ndarray, overwrite: bool = False) -> None:
    """Write linear RGB clipped to [0, 1], sRGB-encoded, as an 8-bit PNG, atomically."""
    from PIL import Image

    enc = spectra.srgb_encode(np.clip(rgb, 0.0, 1.0))
    img = Image.fromarray(np.round(enc * 255.0).astype(np.uint8), mode="RGB")
    with atomic_write(path, overwrite=overwrite) as tmp:
        img.save(tmp, format="PNG")


def output_paths(path: str | Path, overwrite: bool = False) -> tuple[Path, Path]:
    """(.exr, .png) paths of an input image saved at ``path``; raises if either exists and
    ``overwrite`` is false (so a command can check before doing any work)."""
    path = Path(path)
    if path.suffix.lower() not in (".exr", ".png"):
        raise SpecGenError(f"{path}: output must end in .exr or .png")
    exr, png = path.with_suffix(".exr"), path.with_suffix(".png")
    if not overwrite:
        for p in (exr, png):
            if p.exists():
                raise OutputExistsError(f"{p}: already exists (pass --overwrite to replace it)")
    return exr, png


def save_input(rgb: np.ndarray, path: str | Path, overwrite: bool = False) -> list[Path]:
    """Save an input image as linear EXR *and* 8-bit sRGB PNG beside each other.

    ``path`` ends in .exr or .png; the sibling with the other suffix is written too. Both targets
    are checked before anything is written.
    """
    exr, png = output_paths(path, overwrite)
    write_exr_rgb(exr, rgb, overwrite=overwrite)
    write_png_srgb(png, rgb, overwrite=overwrite)
    return [exr, png]


# -- loading user images --------------------------------------------------------------------------

def read_image(path: str | Path, encoding: str = "auto") -> np.ndarray:
    """Read an image as linear float (H, W, C) (:func:`specgen_addon.photo.read.read_photo`): EXR
    values as stored; 8/16-bit PNG/JPEG/TIFF normalised to [0, 1] and sRGB-decoded unless
    ``encoding="linear"`` (alpha kept linear)."""
    photo = read_photo(path, encoding=encoding)
    warn_notes(photo, path)
    return photo.rgb


@dataclass(frozen=True)
class SphereCrop:
    """The canonical input cut from a user's image, and how it was cut.

    ``copied`` is True when the sphere was framed exactly on whole pixels at the canonical size and
    copied pixel for pixel (a canonical render); False when it was resampled (off the grid,
    antialiased, another size: every camera photo). The two kinds of input look different to the
    network, and the shipped weights hold one network for each
    (:func:`specgen_addon.model.shipped_weights`). ``circle`` is the circle used (cx, cy, r in
    the source image's pixels, centres at +0.5) and ``circle_source`` how it was obtained;
    ``saturated`` marks the crop's pixels that saw a saturated source pixel (None: none).
    """

    image: np.ndarray  # (size, size, 3) linear sRGB, float32
    copied: bool
    circle: tuple[float, float, float] | None = None
    circle_source: str = ""
    saturated: np.ndarray | None = None   # (size, size) bool
    encoding: str = ""
    white_gains: np.ndarray | None = None  # (3,) per-channel white-balance gains applied (None: as shot)
    white_source: str = ""   # where the gains came from: "from the patch", "from the colour checker", "as the photo's"
    white_note: str = ""     # the colour checker found and its fit, for the run's report ("" without one)
    read_scale: float = 1.0  # width read / the file's width (< 1: downsampled on reading; ``circle`` is in the read pixels)

    @property
    def file_circle(self) -> tuple[float, float, float] | None:
        """:attr:`circle` in the file's pixels (as ``--circle`` takes it), or None."""
        if self.circle is None:
            return None
        return tuple(float(v) / self.read_scale for v in self.circle)

    def describe(self) -> str:
        """One line for a run's report: the circle (in the file's pixels), how it was found, and
        the saturated share."""
        if self.circle is None:
            return "sphere: as given"
        cx, cy, r = self.file_circle
        sat = ""
        if self.saturated is not None and self.saturated.any():
            sat = f"; {100 * self.saturated.mean() / (np.pi / 4):.1f} % of the sphere saturated (left out of the fit)"
        enc = f"; decoded {self.encoding}" if self.encoding else ""
        wb = ""
        if self.white_gains is not None:
            wb = f"; white balance {self.white_source or 'from the patch'}: gains " + \
                "R {:.3f} G {:.3f} B {:.3f}".format(*self.white_gains)
        read = "" if self.read_scale == 1.0 else f"; read at {self.read_scale:.3g}× the file's size"
        return f"sphere: centre ({cx:.2f}, {cy:.2f}) px, radius {r:.2f} px ({self.circle_source}){enc}{wb}{read}{sat}"


#: How many of :meth:`PhotoSource.crop`'s crops are kept (a photo and its chrome ball's).
_CROPS_KEPT = 4
_CROPS: dict[tuple, tuple[SphereCrop, list]] = {}


def _file_stamp(path) -> tuple[int, int] | None:
    """A file's modification time and size (None where it cannot be read: the load then says why)."""
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


@dataclass(frozen=True)
class PhotoSource:
    """A photo file and the user's choices about it: how its codes are encoded
    (:data:`specgen_addon.photo.read.ENCODINGS`), a white level above which values count as
    saturated, where the sphere is: a circle (cx, cy, r in pixels, x right, y down, from the
    top-left corner) or a mask file (the sphere white), else found in the photo; and its white
    balance: as shot, a neutral patch (x, y, w, h in pixels) or the greys of a colour checker in the
    photo (``colour_checker``, :mod:`specgen_addon.photo.colour_checker`) balanced to ``white_target``
    (linear RGB, default neutral; :mod:`specgen_addon.photo.white_balance`), or gains given."""

    path: Path
    encoding: str = "auto"
    white_level: float | None = None
    circle: tuple[float, float, float] | None = None
    mask: Path | None = None
    white_patch: tuple[float, float, float, float] | None = None
    white_target: tuple[float, float, float] | None = None
    white_gains: tuple[float, float, float] | None = None
    colour_checker: bool = False

    def crop(self, size: int = CANONICAL_SIZE) -> SphereCrop:
        """The sphere's crop (:func:`load_sphere_crop`). The last few are kept while their files
        are unchanged: a run that estimates or unwraps the light crops the photo before the
        network does (finding the ball is most of a second); the warnings are said again."""
        key = (self, size, _file_stamp(self.path), None if self.mask is None else _file_stamp(self.mask))
        try:
            hit = _CROPS.pop(key, None)
        except TypeError:                 # a field given as a list: not kept
            key, hit = None, None
        if hit is None:
            with warnings.catch_warnings(record=True) as said:
                warnings.simplefilter("always")
                made = load_sphere_crop(self.path, size, encoding=self.encoding, white_level=self.white_level,
                                        circle=self.circle, mask=self.mask, white_patch=self.white_patch,
                                        white_target=self.white_target, white_gains=self.white_gains,
                                        colour_checker=self.colour_checker)
            hit = (made, [(w.message, w.category) for w in said])
        if key is not None:
            _CROPS[key] = hit
        while len(_CROPS) > _CROPS_KEPT:
            _CROPS.pop(next(iter(_CROPS)))
        made, said = hit
        for message, category in said:
            warnings.warn(message, category, stacklevel=2)
        return replace(made, image=made.image.copy(),
                       saturated=None if made.saturated is None else made.saturated.copy())

    @property
    def linear(self) -> bool:
        """Whether the photo's values are unclipped linear light (a float file)."""
        return stores_floats(self.path)


def parse_circle(text: str, option: str = "--circle") -> tuple[float, float, float]:
    """``"X,Y,R"`` (pixels) → (cx, cy, r); one clear sentence naming ``option`` when it is not
    three numbers with R > 0."""
    try:
        values = tuple(float(v) for v in str(text).replace(" ", "").split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(np.isfinite(values)) or values[2] <= 0:
        raise ImageInputError(f"{option} takes X,Y,R in pixels (centre from the top-left corner, radius > 0), "
                              f"got {text!r}")
    return values  # type: ignore[return-value]


def read_mask(path: str | Path, shape: tuple[int, int]) -> np.ndarray:
    """A mask file as coverage in [0, 1] (H, W): its alpha if it has one, else its brightness."""
    photo = read_photo(path, encoding="linear")
    arr = photo.rgb
    cov = arr[..., 3] if arr.shape[-1] == 4 and not np.all(arr[..., 3] > 0.999) else arr[..., :3].mean(-1)
    if cov.shape != tuple(shape):
        raise ImageInputError(f"{path}: the mask is {cov.shape[1]}×{cov.shape[0]} pixels, the photo "
                              f"{shape[1]}×{shape[0]}")
    return np.clip(cov, 0.0, 1.0)


def mask_circle(coverage: np.ndarray) -> tuple[float, float, float]:
    """The circle of a soft or hard mask: centroid and area-equivalent radius (pixels)."""
    area = float(coverage.sum())
    if area < np.pi * MIN_SPHERE_RADIUS_PX ** 2 * 0.5:
        raise ImageInputError("the mask covers no sphere")
    ys, xs = np.mgrid[0:coverage.shape[0], 0:coverage.shape[1]]
    return (float((coverage * (xs + 0.5)).sum() / area), float((coverage * (ys + 0.5)).sum() / area),
            float(np.sqrt(area / np.pi)))


def load_sphere_image(path: str | Path, size: int = CANONICAL_SIZE) -> np.ndarray:
    """A user's sphere image as the canonical input: linear sRGB (size, size, 3) float32.

    Raises :class:`~specgen_addon.common.errors.ImageInputError` if the file is unreadable, has other than
    3 (RGB) or 4 (RGBA) channels, holds NaN/Inf, or shows no sphere.
    """
    return load_sphere_crop(path, size).image


def check_white_balance_choice(white_patch, colour_checker: bool) -> None:
    """One source of white balance at most: a patch or a colour checker, not both."""
    if white_patch is not None and colour_checker:
        raise ImageInputError("--white-patch and --colour-checker both set the white balance: give one")


def load_sphere_crop(path: str | Path, size: int = CANONICAL_SIZE, encoding: str = "auto",
                     white_level: float | None = None, circle: tuple[float, float, float] | None = None,
                     mask: str | Path | None = None,
                     white_patch: tuple[float, float, float, float] | None = None,
                     white_target: tuple[float, float, float] | None = None,
                     white_gains: tuple[float, float, float] | None = None,
                     colour_checker: bool = False) -> SphereCrop:
    """:func:`load_sphere_image`, with whether the sphere was copied or resampled, the circle used,
    the saturated pixels and the white balance (:class:`PhotoSource` names the choices)."""
    path = Path(path)
    check_white_balance_choice(white_patch, colour_checker)
    photo = read_photo(path, encoding=encoding, white_level=white_level)
    warn_notes(photo, path)
    arr = photo.rgb
    gains, source, note = None, "", ""
    try:
        if white_patch is not None:
            gains, source = patch_gains(arr, photo.saturated, white_patch, white_target, photo.scale), "from the patch"
        if colour_checker:
            found = find_checker(arr, photo.saturated, photo.scale,
                                 key=(str(path.resolve()), _file_stamp(path), encoding, white_level))
            balance = checker_balance(found, white_target)
            gains, source, note = balance.gains, "from the colour checker", balance.describe()
        if white_gains is not None:
            gains = np.asarray(white_gains, np.float64) * (1.0 if gains is None else gains)
            source = source or "as the photo's"
        if gains is not None:
            arr = arr.copy()
            arr[..., :3] *= gains.astype(arr.dtype)
        return replace(_crop_photo(arr, photo, size, circle, mask), white_gains=gains, white_source=source,
                       white_note=note, read_scale=photo.scale)
    except ImageInputError as exc:
        raise ImageInputError(f"{path}: {exc}") from None


def _crop_photo(arr: np.ndarray, photo, size: int, circle, mask) -> SphereCrop:
    """The crop of a read photo's pixels ``arr``: about the circle given, the mask's, or the one found."""
    if circle is not None or mask is not None:
        scale = photo.scale   # a photo downsampled on reading: the user's circle is in the file's pixels
        if mask is not None:
            cov = read_mask(mask, arr.shape[:2])
            c = mask_circle(cov)
            return _crop_at(arr, c, size, f"from the mask {Path(mask).name}", photo)
        cx, cy, r = (v * scale for v in circle)
        return _crop_at(arr, (cx, cy, r), size, "given", photo)
    crop = crop_sphere(arr, size)
    return replace(crop, saturated=_saturated_in_crop(photo.saturated, crop.circle, size),
                   encoding=photo.encoding)


def write_circle_preview(path: str | Path, source: PhotoSource, circle: tuple[float, float, float],
                         overwrite: bool = False) -> Path:
    """The photo (sRGB, 8-bit) with ``circle`` (in the read photo's pixels) drawn in red, a line
    about a two-hundredth of the radius wide (at least a pixel), and its centre marked."""
    rgb = read_photo(source.path, encoding=source.encoding).rgb[..., :3]
    top = float(np.percentile(rgb, 99.9)) or 1.0
    img = np.round(spectra.srgb_encode(np.clip(rgb / top, 0.0, 1.0)) * 255.0).astype(np.uint8)
    cx, cy, r = circle
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    dist = np.hypot(xx + 0.5 - cx, yy + 0.5 - cy)
    line = max(0.6, r / 200.0)
    img[(np.abs(dist - r) < line) | (dist < 2 * line)] = (255, 40, 40)
    return write_png8(path, img, overwrite=overwrite)


def _crop_at(arr: np.ndarray, circle: tuple[float, float, float], size: int, source: str, photo) -> SphereCrop:
    """The crop about a circle the user gave (directly or as a mask), checked to lie in the frame."""
    cx, cy, r = circle
    h, w = arr.shape[:2]
    if r < MIN_SPHERE_RADIUS_PX / 2 or cx - r < -0.5 * r or cy - r < -0.5 * r or cx + r > w + 0.5 * r \
            or cy + r > h + 0.5 * r:
        raise ImageInputError(f"the circle ({cx:g}, {cy:g}, r {r:g}) does not lie in the {w}×{h} image")
    rgb = np.clip(np.asarray(arr[..., :3], np.float64), 0.0, None)
    return SphereCrop(_resample_circle(rgb, cx, cy, r, size), False, (cx, cy, r), source,
                      _saturated_in_crop(photo.saturated, (cx, cy, r), size), photo.encoding)


def _saturated_in_crop(saturated: np.ndarray | None, circle, size: int) -> np.ndarray | None:
    """The crop's pixels that any saturated source pixel reaches (through the resampling)."""
    if saturated is None or circle is None or not saturated.any():
        return None
    spread = _resample_circle(np.repeat(saturated[..., None].astype(np.float64), 3, -1), *circle, size)
    return spread[..., 0] > 1e-3


def prepare_sphere_array(arr: np.ndarray, size: int = CANONICAL_SIZE) -> np.ndarray:
    """Find, crop and resample the sphere of a linear RGB/RGBA array (H, W, 3|4) to (size, size, 3)."""
    return crop_sphere(arr, size).image


def crop_sphere(arr: np.ndarray, size: int = CANONICAL_SIZE) -> SphereCrop:
    """:func:`prepare_sphere_array`, with whether the sphere was copied or resampled."""
    raw = np.asarray(arr)
    if raw.dtype.kind not in "biuf":
        raise ImageInputError(f"expected an array of numbers, got dtype {raw.dtype}")
    arr = raw.astype(np.float64, copy=False)
    if arr.ndim == 3 and min(arr.shape[:2]) < 2 * MIN_SPHERE_RADIUS_PX:
        raise ImageInputError(f"image of {arr.shape[1]}×{arr.shape[0]} pixels is too small to hold a sphere")
    if arr.ndim != 3 or arr.shape[-1] not in (3, 4):
        channels = arr.shape[-1] if arr.ndim == 3 else 1
        raise ImageInputError(f"expected an RGB or RGBA image, got {channels} channel(s) "
                              f"(shape {arr.shape})")
    if not np.all(np.isfinite(arr)):
        raise ImageInputError("image holds NaN or Inf values")
    rgb = np.clip(arr[..., :3], 0.0, None)
    if arr.shape[-1] == 4 and not np.all(arr[..., 3] > 0.5):  # an all-opaque alpha masks nothing
        coverage = np.clip(arr[..., 3], 0.0, 1.0)
        mask = coverage > 0.5
        if mask.sum() < np.pi * MIN_SPHERE_RADIUS_PX ** 2 * 0.5:
            raise ImageInputError("the alpha channel covers no sphere")
        contrast = coverage
        rough = _circle_of_mask(mask, fit_outline=False)
        source = "from the alpha channel"
    else:
        try:
            mask, contrast = _foreground(rgb)
            rough = _circle_of_mask(mask, fit_outline=True)
            source = "found: foreground outline"
        except ImageInputError as exc:
            try:  # JPEG noise around a black background: ignore the darkest 1 % of the range
                mask, contrast = _foreground(rgb, noise_floor=0.01)
                rough = _circle_of_mask(mask, fit_outline=True)
                source = "found: foreground outline"
            except ImageInputError:
                if _clean_background(rgb):   # a render's outline that is not a circle
                    raise exc from None
                # a camera photo: the unlit side merges with the ground, a stand touches the ball
                return _photo_crop(rgb, size, exc)
        if not _clean_background(rgb):
            return _photo_crop(rgb, size, None, fallback=(mask, contrast, rough))
    framed = _whole_pixel_framing(rough, mask)
    if framed is not None:  # a sphere already framed exactly stays untouched
        return SphereCrop(_resample_circle(rgb, *framed, size), copied=2.0 * framed[2] == size,
                          circle=framed, circle_source=source + ", whole pixels")
    refined = _refined_circle(contrast, rough)
    return SphereCrop(_resample_circle(rgb, *refined, size), copied=False, circle=tuple(refined),
                      circle_source=source)


def _clean_background(rgb: np.ndarray) -> bool:
    """Whether the background is a render's: a single colour (black, say) along half of the
    border or more (the rest: a sphere touching the frame), so the foreground's outline is the
    sphere's; a camera's background never is."""
    lum = luminance(rgb)
    border = np.concatenate([lum[:2].ravel(), lum[-2:].ravel(), lum[:, :2].ravel(), lum[:, -2:].ravel()])
    top = float(np.percentile(lum, 99.5))
    return top > 0 and float(np.mean(np.abs(border - np.median(border)) <= 1e-3 * top)) >= 0.5


def _photo_crop(rgb: np.ndarray, size: int, error: ImageInputError | None, fallback=None) -> SphereCrop:
    """The crop of a camera photo about the ball found from its lit outline
    (:func:`specgen_addon.photo.sphere_detect.find_ball`); where that finds nothing, the foreground's
    circle (``fallback``), else ``error``."""
    try:
        found = find_ball(rgb)
    except ImageInputError as exc:
        if fallback is None:
            raise (error or exc) from None
        _, contrast, rough = fallback
        refined = _refined_circle(contrast, rough)
        return SphereCrop(_resample_circle(rgb, *refined, size), False, tuple(refined), "found: foreground outline")
    return SphereCrop(_resample_circle(rgb, *found.circle, size), False, found.circle,
                      f"found: lit outline, {found.arc:.0%} of it seen, rms {found.rms_px:.2f} px")


def _ndimage():
    """The numpy ndimage twin (:mod:`specgen_addon.photo.ndimage_np`): one implementation on every path,
    the CLI's and a stock Blender's alike (scipy serves the tests as an oracle)."""
    return ndimage_np


def _ransac_circle(pts: np.ndarray, residual_threshold: float, max_trials: int):
    """RANSAC circle fit (numpy, :func:`specgen_addon.photo.ndimage_np.ransac_circle`): (model, inliers)."""
    return ransac_circle(pts, residual_threshold=residual_threshold, max_trials=max_trials)


def _foreground(rgb: np.ndarray, noise_floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Pixels that differ from the background, whose colour is the median of the image border,
    and every pixel's contrast: its largest per-channel departure from that colour, which is
    proportional to how much of the pixel the sphere covers.

    ``noise_floor`` (a fraction of the bright end of the luminance) treats darker pixels of a
    black background as background, e.g. compression noise of a JPEG.
    """
    ndimage = _ndimage()

    lum = luminance(rgb)
    if not np.percentile(lum, 99.5) > 0:
        raise ImageInputError("image is blank: no sphere found")
    contrast = rgb.max(axis=-1)
    if noise_floor > 0:
        fg = ndimage.binary_opening(lum > noise_floor * np.percentile(lum, 99.5), iterations=1)
    elif np.mean(lum == 0) >= 0.1:
        fg = lum > 0  # a render on an exactly black background: every lit pixel is the object
    else:
        border = np.concatenate([rgb[:2].reshape(-1, 3), rgb[-2:].reshape(-1, 3),
                                 rgb[:, :2].reshape(-1, 3), rgb[:, -2:].reshape(-1, 3)])
        background = np.median(border, axis=0)
        dist = np.abs(rgb - background).max(axis=-1)
        border_dist = np.abs(border - background).max(axis=-1)
        spread = np.percentile(dist, 99.5)
        if not spread > 0:
            raise ImageInputError("image is blank (a single colour): no sphere found")
        threshold = max(0.05 * spread, 4.0 * float(np.percentile(border_dist, 90)), 1e-6)
        fg = ndimage.binary_opening(dist > threshold, iterations=1)
        contrast = dist
    labels, count = ndimage.label(fg)
    if count == 0:
        raise ImageInputError("no sphere found (nothing stands out from the background)")
    sizes = ndimage.sum(fg, labels, index=np.arange(1, count + 1))
    largest = labels == (1 + int(np.argmax(sizes)))
    return ndimage.binary_fill_holes(largest), contrast


def _circle_of_mask(mask: np.ndarray, fit_outline: bool) -> tuple[float, float, float]:
    """(cx, cy, r) in pixel units (pixel centres at integer + 0.5) of the sphere in ``mask``, to
    about half a pixel (:func:`_refined_circle` takes it further)."""
    ndimage = _ndimage()

    area = float(mask.sum())
    ys, xs = np.nonzero(mask)
    if area < np.pi * MIN_SPHERE_RADIUS_PX ** 2 * 0.5:
        raise ImageInputError("no sphere found (foreground too small)")
    cx, cy, r = xs.mean() + 0.5, ys.mean() + 0.5, np.sqrt(area / np.pi)
    if fit_outline:
        edge = mask & ~ndimage.binary_erosion(mask)
        ey, ex = np.nonzero(edge)
        pts = np.stack([ex + 0.5, ey + 0.5], -1).astype(np.float64)
        model, inliers = (None, None)
        if len(pts) >= 10:
            with warnings.catch_warnings():  # degenerate triples (collinear edge points) warn
                warnings.simplefilter("ignore")
                # tolerances relative to the radius: an upscaled photo's outline steps by the factor
                model, inliers = _ransac_circle(pts, residual_threshold=max(1.5, 0.02 * r), max_trials=200)
        if model is None or inliers is None or inliers.mean() <= 0.5:
            raise ImageInputError("no sphere found (the foreground's outline is not a circle; "
                                  "give the sphere's circle or a mask, or an alpha channel masking it)")
        fx, fy, fr = (float(v) for v in model.params)
        # the outline passes through edge-pixel centres, half a pixel inside the silhouette
        cx, cy, r = fx, fy, fr + 0.5
    # the disc must be mostly filled and mostly inside the frame
    box, disc = _disc_in_frame(mask.shape, cx, cy, r)
    inside = disc.sum() / max(np.pi * r * r, 1.0)
    filled = (disc & mask[box]).sum() / max(disc.sum(), 1)
    if r < MIN_SPHERE_RADIUS_PX or inside < 0.8 or filled < 0.7:
        raise ImageInputError(f"no sphere found (best circle: centre ({cx:.0f}, {cy:.0f}), radius "
                              f"{r:.0f} px, {filled:.0%} filled, {inside:.0%} inside the frame)")
    return float(cx), float(cy), float(r)


def _refined_circle(contrast: np.ndarray, rough: tuple[float, float, float]) -> tuple[float, float, float]:
    """``rough`` refined to a fraction of a pixel from the outline's partly covered pixels
    (:func:`specgen_addon.photo.sphere_edge.refine_circle`; ``contrast``, H×W, is proportional to each
    pixel's coverage by the sphere); ``rough`` itself where the outline cannot be measured."""
    cx, cy, r = rough
    refined = refine_circle(np.asarray(contrast, np.float64), cx, cy, r)
    tol = max(1.5, 0.015 * r)   # relative to the radius: the same at 512 px and at 8000 px
    if refined is None or abs(refined[2] - r) > tol or np.hypot(refined[0] - cx, refined[1] - cy) > tol:
        return rough
    return refined


def _disc_in_frame(shape: tuple[int, int], cx: float, cy: float, r: float
                   ) -> tuple[tuple[slice, slice], np.ndarray]:
    """The frame's part of the disc's bounding box, and the pixels there whose centre lies inside
    the disc (all others of the frame lie outside it)."""
    h, w = shape
    y0, y1 = max(int(np.floor(cy - r)), 0), min(int(np.ceil(cy + r)) + 1, h)
    x0, x1 = max(int(np.floor(cx - r)), 0), min(int(np.ceil(cx + r)) + 1, w)
    yy, xx = np.mgrid[y0:max(y1, y0), x0:max(x1, x0)]
    return (slice(y0, max(y1, y0)), slice(x0, max(x1, x0))), \
        (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 < r * r


def _whole_pixel_framing(circle: tuple[float, float, float],
                         mask: np.ndarray) -> tuple[float, float, float] | None:
    """The circle of the whole-pixel square around ``circle`` when ``mask`` is exactly that
    square's inscribed disc, point-sampled (pixels whose centre lies inside), as a canonical render
    is; a few missing pixels (a black limb) are allowed. Such a sphere is copied pixel for pixel.
    Else None: an antialiased or off-grid outline, for the sub-pixel path."""
    cx, cy, r = circle
    x0, x1, y0, y1 = (round(cx - r), round(cx + r), round(cy - r), round(cy + r))
    side = max(x1 - x0, y1 - y0)
    fx, fy, fr = (x0 + x1) / 2.0, (y0 + y1) / 2.0, side / 2.0
    box, disc = _disc_in_frame(mask.shape, fx, fy, fr)
    covered = int((mask[box] & disc).sum())
    if int(mask.sum()) != covered or int(disc.sum()) - covered > 0.1 * 2 * np.pi * fr:
        return None
    return fx, fy, fr


def _resample_circle(rgb: np.ndarray, cx: float, cy: float, r: float, size: int) -> np.ndarray:
    """Bilinear resample of the square around the circle onto the canonical pixel grid (area
    pre-filter when shrinking), background outside the unit disc set to 0.

    Only the square and a margin the filters reach are read, so a large photo costs little.
    (Replacing the outline pixels by the sphere's inside colour before resampling was measured and
    cost the shipped network 0.4 dB more than leaving them mixed with the background;
    lab/notebook/resampled-network.md.)
    """
    ndimage = _ndimage()

    scale = 2.0 * r / size  # source pixels per output pixel
    reach = int(np.ceil(2.0 * max(scale, 1.0))) + 2  # the pre-filter's and interpolation's reach
    h, w = rgb.shape[:2]
    x0, y0 = max(int(np.floor(cx - r)) - reach, 0), max(int(np.floor(cy - r)) - reach, 0)
    x1, y1 = min(int(np.ceil(cx + r)) + reach, w), min(int(np.ceil(cy + r)) + reach, h)
    src = rgb[y0:y1, x0:x1]
    cx, cy = cx - x0, cy - y0
    if scale > 1.0:
        src = ndimage.gaussian_filter(src, sigma=(0.5 * scale, 0.5 * scale, 0), mode="nearest")
    x, y = pixel_grid(size)
    sx = cx + x * r - 0.5           # source column coordinate (pixel centres at integers)
    sy = cy - y * r - 0.5
    out = np.stack([ndimage.map_coordinates(src[..., c], [sy, sx], order=1, mode="nearest")
                    for c in range(3)], -1)
    out[x * x + y * y >= 1.0] = 0.0
    return out.astype(np.float32)
