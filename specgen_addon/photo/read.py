"""Camera files as cameras make them: every bit kept, the encoding a choice, saturation found.

:func:`read_photo` reads a photo into linear float RGB(A) and says which of its pixels were
saturated (any colour channel at the format's full scale, or at a white level the user gives),
so that every fit can leave them out.

* 8/16-bit PNG, TIFF, JPEG, TGA ...: integer codes, sRGB-decoded by default or taken as stored
  (``encoding="linear"``); a 16-bit file is read through OpenImageIO a band of rows at a time, so
  it keeps all 16 bits at any size (Pillow reads 16-bit RGB as 8-bit). Saturated: a code at the
  maximum (255, 65535).
* OpenEXR, Radiance HDR and floating-point TIFF: linear as stored; nothing counts as saturated unless ``white_level``
  is given (a clipped highlight core in an EXR looks like a real one).
* Camera RAW (DNG, CR2, CR3, NEF, ARW, RAF, ORF, RW2 ...): developed by LibRaw (``rawpy``, command
  line only) linearly, as shot white balance, sRGB primaries, no tone curve and no automatic
  brightening; saturated: a sensor value at the file's white level.

In a stock Blender (no Pillow, no rawpy) OpenImageIO reads PNG, TIFF, JPEG, EXR and HDR; camera RAW
is refused there with one sentence.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from specgen_addon.common.errors import ImageInputError
from specgen_addon.common.image_io import ImageIOError, read_exr, read_float_image
from specgen_addon.common.limits import MAX_WORK_SIDE
from specgen_addon.photo import image_checks
from specgen_addon.photo.ndimage_np import binary_dilation
from specgen_addon.spectral import spectra

#: How integer codes become linear values: "auto" (sRGB for 8/16-bit files), "srgb", "linear".
ENCODINGS = ("auto", "srgb", "linear")
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf",
                ".rw2", ".pef", ".srw", ".3fr", ".iiq", ".rwl", ".x3f", ".erf", ".kdc", ".mos", ".mrw")
FLOAT_SUFFIXES = (".exr", ".hdr")


@dataclass
class Photo:
    """A photo read as linear RGB(A), with its saturated pixels and how it was decoded."""

    rgb: np.ndarray                 # (H, W, 3|4) float32, linear (alpha linear)
    saturated: np.ndarray           # (H, W) bool
    encoding: str                   # "sRGB-decoded", "linear", "linear (float)", "RAW, developed linearly"
    bits: int                       # bits per channel of the file (32 for float)
    notes: list[str] = field(default_factory=list)
    scale: float = 1.0              # width read / the file's width (< 1 where downsampled on reading)

    @property
    def saturated_count(self) -> int:
        return int(self.saturated.sum())


def check_encoding(encoding: str) -> str:
    if encoding not in ENCODINGS:
        raise ImageInputError(f"unknown encoding {encoding!r}; choose one of {', '.join(ENCODINGS)}")
    return encoding


def check_white_level(white_level: float | None) -> None:
    """A white level (linear units of the decoded values) is None or a positive number."""
    if white_level is not None and not (math.isfinite(white_level) and white_level > 0):
        raise ImageInputError(f"the white level must be a positive number, got {white_level}")


def read_photo(path: str | Path, encoding: str = "auto", white_level: float | None = None) -> Photo:
    """Read a photo file (module docstring); ``white_level`` (linear units of the decoded values)
    marks every pixel with a colour value at or above it as saturated too."""
    path = Path(path)
    check_encoding(encoding)
    check_white_level(white_level)
    if not path.is_file():
        raise ImageInputError(f"{path}: {'is a folder, not an image file' if path.is_dir() else 'no such image file'}")
    suffix = path.suffix.lower()
    if suffix in RAW_SUFFIXES:
        photo = _read_raw(path)
    else:
        image_checks.check_image_header(path)   # pixel limit, before any decoding
        if suffix in FLOAT_SUFFIXES or stores_floats(path):
            photo = _read_float(path)
        else:
            photo = _read_integer(path, encoding == "linear")
    if white_level is not None:
        photo.saturated |= np.any(photo.rgb[..., :3] >= white_level * (1.0 - 1e-6), axis=-1)
    return photo   # the saturated share is reported with the circle (SphereCrop.describe)


def stores_floats(path: str | Path) -> bool:
    """Whether a file holds floating-point pixels (an EXR or HDR, or a 16/32-bit float TIFF):
    linear light as stored, not clipped at a full scale. Read from the header (OpenImageIO)."""
    path = Path(path)
    if path.suffix.lower() in FLOAT_SUFFIXES:
        return True
    if path.suffix.lower() not in (".tif", ".tiff"):
        return False
    with _oiio_opened(path) as opened:
        if opened is None:
            return False
        oiio, inp = opened
        return inp.spec().format.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE)


@contextlib.contextmanager
def _oiio_opened(path: Path) -> Iterator[tuple | None]:
    """(OpenImageIO, the file opened with it), closed after the block; None without OpenImageIO
    or where it cannot open the file."""
    try:
        import OpenImageIO as oiio
    except ImportError:
        yield None
        return
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        yield None
        return
    try:
        yield oiio, inp
    finally:
        inp.close()


def _read_float(path: Path) -> Photo:
    if path.suffix.lower() == ".exr":
        try:
            channels, _ = read_exr(path)
        except ImageIOError as exc:
            raise ImageInputError(str(exc)) from None   # names the file and what is wrong
        names = [n for n in ("R", "G", "B", "A") if n in channels]
        if names[:3] != ["R", "G", "B"]:
            raise ImageInputError(f"{path}: EXR needs R, G, B channels, has "
                                  f"{', '.join(sorted(channels))} ({len(channels)} channels)")
        arr = np.stack([np.asarray(channels[n], np.float32) for n in names], -1)
    else:
        arr = _read_oiio_float(path)
    width = arr.shape[1]
    arr = image_checks.clean_exr_pixels(image_checks.downsample_linear(arr), path)
    return Photo(arr, np.zeros(arr.shape[:2], bool), "linear (float)", 32, scale=arr.shape[1] / width)


def _read_oiio_float(path: Path) -> np.ndarray:
    return _as_rgba(read_float_image(path, ImageInputError), path)


def _as_rgba(data: np.ndarray, path: Path) -> np.ndarray:
    """1 channel → RGB, 2 → RGBA (gray + alpha), 3/4 as they are, more refused."""
    c = data.shape[-1]
    if c == 1:
        return np.repeat(data, 3, axis=-1)
    if c == 2:
        return np.concatenate([np.repeat(data[..., :1], 3, axis=-1), data[..., 1:]], -1)
    if c in (3, 4):
        return data
    raise ImageInputError(f"{path}: expected an RGB or RGBA image, got {c} channels")


def _read_integer(path: Path, linear: bool) -> Photo:
    encoding = "linear" if linear else "sRGB-decoded"
    sixteen = _read_oiio_uint16(path, linear)
    if sixteen is not None:
        return sixteen
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError:   # a stock Blender: its bundled OpenImageIO decodes the file
        arr = _read_oiio_float(path)
        width = arr.shape[1]
        saturated = np.any(arr[..., :3] >= 1.0 - 0.5 / 65535, axis=-1)
        arr = image_checks.downsample_linear(arr)
        saturated = _reduce_any(saturated, arr.shape[:2])
        if not linear:
            arr[..., :3] = spectra.srgb_decode(arr[..., :3]).astype(np.float32)
        return Photo(arr, saturated, encoding, 8, scale=arr.shape[1] / width)
    sat: list = []
    try:
        with image_checks._unlimited_pil(), Image.open(path) as im:   # our pixel limit: from the header
            bits = 16 if im.mode.startswith("I") else 8
            width = im.size[0]
            arr = image_checks.pil_to_linear(im, path, linear=linear, saturated=sat)
    except (UnidentifiedImageError, OSError) as exc:
        raise ImageInputError(f"{path}: cannot read image ({exc})") from None
    return Photo(arr, sat[0] if sat else np.zeros(arr.shape[:2], bool), encoding, bits,
                 scale=arr.shape[1] / width)


def _reduce_any(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A full-resolution mask reduced to a box-downsampled image's shape: any pixel of the box."""
    oh, ow = shape
    if mask.shape == (oh, ow):
        return mask
    f = mask.shape[0] // oh
    return mask[:oh * f, :ow * f].reshape(oh, f, ow, f).any(axis=(1, 3))


def _read_oiio_uint16(path: Path, linear: bool) -> Photo | None:
    """A 16-bit integer file through OpenImageIO, a band of rows at a time, all 16 bits kept and
    box-downsampled in linear light to :data:`MAX_WORK_SIDE`; None for any other file (or without
    OpenImageIO)."""
    with _oiio_opened(path) as opened:
        if opened is None:
            return None
        oiio, inp = opened
        spec = inp.spec()
        if spec.format != oiio.UINT16 or spec.nchannels not in (1, 2, 3, 4):
            return None
        w, h, c = spec.width, spec.height, spec.nchannels
        factor = max(1, math.ceil(max(w, h) / MAX_WORK_SIDE))
        oh, ow = (h // factor, w // factor) if factor > 1 else (h, w)
        out_c = 3 if c in (1, 3) else 4
        out = np.empty((oh, ow, out_c), np.float32)
        sat = np.zeros((oh, ow), bool)
        band = max(1, (1 << 22) // max(1, w * c * factor)) * factor   # rows per band, whole boxes
        for y0 in range(0, oh * factor, band):
            y1 = min(oh * factor, y0 + band)
            codes = np.asarray(inp.read_scanlines(0, 0, y0, y1, 0, 0, c, oiio.UINT16))
            codes = _as_rgba(codes.reshape(y1 - y0, w, c), path).astype(np.uint16, copy=False)
            parts: list = []
            lin = image_checks._decode_downsampled(codes, 65536, out_c == 4, factor, linear, parts)
            out[y0 // factor:y1 // factor] = lin[:, :ow]
            sat[y0 // factor:y1 // factor] = parts[0][:, :ow]
    photo = Photo(out, sat, "linear" if linear else "sRGB-decoded", 16, scale=ow / w)
    if c in (1, 2):
        photo.notes.append("16-bit grayscale" + ("+alpha image converted to RGBA" if c == 2 else " image converted to RGB"))
    if factor > 1:
        photo.notes.append(f"16-bit {w}×{h} downsampled {factor}× to {ow}×{oh} (all 16 bits kept)")
    return photo


def _read_raw(path: Path) -> Photo:
    try:
        import rawpy
    except ImportError:
        raise ImageInputError(f"{path}: camera RAW files need the rawpy package (LibRaw), which the "
                              "command line has and a stock Blender does not; convert the RAW to a "
                              "16-bit linear TIFF and pass --linear") from None
    try:
        with rawpy.imread(str(path)) as raw:
            rgb = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True,
                                  output_color=rawpy.ColorSpace.sRGB, user_flip=0)
            levels = np.asarray(raw.raw_image_visible)
            white = float(raw.white_level)
            sensor_sat = levels >= white
    except (rawpy.LibRawError, OSError, ValueError) as exc:
        raise ImageInputError(f"{path}: cannot read camera RAW ({type(exc).__name__}: {exc})") from None
    image_checks.check_pixel_count(rgb.shape[1], rgb.shape[0], str(path))
    arr = rgb.astype(np.float32) / 65535.0
    saturated = np.any(rgb >= 65535, axis=-1)
    if sensor_sat.shape == saturated.shape:
        saturated |= binary_dilation(sensor_sat, iterations=1)   # demosaicking spreads a clipped photosite
    width = arr.shape[1]
    arr = image_checks.downsample_linear(arr)
    saturated = _reduce_any(saturated, arr.shape[:2])
    return Photo(arr, saturated, "RAW, developed linearly (as shot white balance, no tone curve)", 16,
                 scale=arr.shape[1] / width)


def warn_notes(photo: Photo, path: str | Path) -> None:
    """Report a photo's conversion notes as :class:`~specgen_addon.photo.image_checks.ImageNote` warnings."""
    if photo.notes:
        warnings.warn(f"{path}: " + "; ".join(photo.notes), image_checks.ImageNote, stacklevel=3)
