"""Input-image checks and conversions: pixel limit from the header, every ordinary photo mode to
linear RGB(A), bounded-memory downsampling, and non-finite/negative EXR pixels.

* :func:`check_image_header` reads only the header (PIL's lazy open, OpenEXR ``header_only``) and
  refuses images over :data:`~specgen_addon.common.limits.MAX_IMAGE_PIXELS` before any pixel is decoded.
* :func:`pil_to_linear` turns grayscale, gray+alpha, palette, 16-bit, RGB, RGBA and CMYK images
  into linear float32 RGB or RGBA (sRGB decoded through a lookup table, alpha kept linear),
  box-averaging in linear light down to :data:`~specgen_addon.common.limits.MAX_WORK_SIDE` a few rows
  at a time, so an 8000² PNG never exists as a float array. Conversions are reported as notes.
* :func:`clean_exr_pixels` refuses NaN/Inf pixel values and clamps negative ones with a warning,
  each with its count.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from specgen_addon.common import limits
from specgen_addon.common.errors import ImageInputError
from specgen_addon.common.limits import MAX_WORK_SIDE


class ImageNote(UserWarning):
    """An input image was converted (mode, bit depth, size) or cleaned; the text says how."""


def image_size(path: str | Path) -> tuple[int, int] | None:
    """(width, height) from the file header only: OpenImageIO (bundled with Blender), else Pillow,
    else OpenEXR for .exr; None when none of them is importable (the decoder then reads it)."""
    path = Path(path)
    try:
        try:
            import OpenImageIO as oiio

            inp = oiio.ImageInput.open(str(path))
            if inp is None:
                reason = oiio.geterror() or "unrecognised image file"
                size = _pil_header_size(path)   # libpng refuses huge headers; Pillow reads them
                if size is None:
                    raise OSError(reason)
                return size
            try:
                spec = inp.spec()
                return int(spec.width), int(spec.height)
            finally:
                inp.close()
        except ImportError:
            pass
        if path.suffix.lower() == ".exr":
            import OpenEXR

            with OpenEXR.File(str(path), header_only=True) as f:
                (x0, y0), (x1, y1) = f.header()["dataWindow"]
                return int(x1 - x0 + 1), int(y1 - y0 + 1)
        from PIL import Image

        with _unlimited_pil(), Image.open(path) as im:
            return im.size
    except ImportError:
        return None
    except Exception as exc:  # unreadable header: one line naming the file
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ImageInputError(f"{path}: cannot read image ({first})") from None


def _pil_header_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from Pillow's lazy open, or None when Pillow is absent or cannot read it."""
    try:
        from PIL import Image

        with _unlimited_pil(), Image.open(path) as im:
            return im.size
    except Exception:  # noqa: BLE001 - the caller reports the first reader's error
        return None


class _unlimited_pil:
    """Pillow's own decompression-bomb guard off: :func:`check_image_header` applies ours."""

    def __enter__(self):
        from PIL import Image

        self.saved = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None

    def __exit__(self, *exc):
        from PIL import Image

        Image.MAX_IMAGE_PIXELS = self.saved


def check_image_header(path: str | Path) -> tuple[int, int] | None:
    """Refuse an image over the pixel limit (or empty) from its header; returns (width, height)
    (None when no header reader is importable)."""
    size = image_size(path)
    if size is None:
        return None
    w, h = size
    check_pixel_count(w, h, str(path))
    return w, h


def check_pixel_count(w: int, h: int, what: str) -> None:
    """Refuse an empty image or one over :data:`MAX_IMAGE_PIXELS` before its pixels are read;
    ``what`` names it in the message (a path, or a Blender image's name)."""
    limit = limits.MAX_IMAGE_PIXELS
    if w * h > limit:
        raise ImageInputError(f"{what}: image is {w}×{h} = {w * h / 1e6:.3g} megapixels; the limit "
                              f"is {limit / 1e6:.3g} megapixels (downscale it first)")
    if w < 1 or h < 1:
        raise ImageInputError(f"{what}: image has no pixels ({w}×{h})")


_SRGB_LUT: dict[int, np.ndarray] = {}


def _srgb_lut(levels: int) -> np.ndarray:
    """Linear value of each code of an ``levels``-level sRGB-encoded channel (float32)."""
    if levels not in _SRGB_LUT:
        x = np.arange(levels, dtype=np.float64) / (levels - 1)
        _SRGB_LUT[levels] = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4) \
            .astype(np.float32)
    return _SRGB_LUT[levels]


def _linear_lut(levels: int) -> np.ndarray:
    """Value of each code of a linearly encoded ``levels``-level channel (float32)."""
    return (np.arange(levels, dtype=np.float64) / (levels - 1)).astype(np.float32)


def _to_linear_rows(rows: np.ndarray, levels: int, has_alpha: bool, linear: bool = False) -> np.ndarray:
    """Integer codes (r, W, C) → float32: colour through the sRGB table (or as stored, ``linear``),
    alpha divided linearly."""
    out = (_linear_lut(levels) if linear else _srgb_lut(levels))[rows]
    if has_alpha:
        out[..., -1] = rows[..., -1].astype(np.float32) / (levels - 1)
    return out


def _decode_downsampled(codes: np.ndarray, levels: int, has_alpha: bool, factor: int,
                        linear: bool = False, saturated: list | None = None) -> np.ndarray:
    """Linear float32 image from integer codes (H, W, C), box-averaged by ``factor`` in linear
    light a band of rows at a time (memory: the codes plus one band). ``saturated``, a list, gets
    the (H', W') mask of output pixels holding any colour code at full scale appended."""
    h, w, c = codes.shape
    colours = c - 1 if has_alpha else c
    if factor <= 1:
        if saturated is not None:
            saturated.append(np.any(codes[..., :colours] >= levels - 1, axis=-1))
        return _to_linear_rows(codes, levels, has_alpha, linear)
    oh, ow = h // factor, w // factor
    out = np.empty((oh, ow, c), np.float32)
    sat = np.zeros((oh, ow), bool)
    band = max(1, (1 << 22) // max(1, w * c * factor))  # ~16 MB of float32 per band
    for y0 in range(0, oh, band):
        y1 = min(oh, y0 + band)
        rows = codes[y0 * factor:y1 * factor, :ow * factor]
        lin = _to_linear_rows(rows, levels, has_alpha, linear)
        out[y0:y1] = lin.reshape(y1 - y0, factor, ow, factor, c).mean(axis=(1, 3))
        sat[y0:y1] = np.any(rows[..., :colours] >= levels - 1, axis=-1) \
            .reshape(y1 - y0, factor, ow, factor).any(axis=(1, 3))
    if saturated is not None:
        saturated.append(sat)
    return out


def pil_to_linear(im, path: str | Path, linear: bool = False, saturated: list | None = None) -> np.ndarray:
    """A Pillow image (header read, pixels not yet decoded) as linear float32 (H, W, 3|4): codes
    sRGB-decoded, or taken as stored with ``linear``. ``saturated`` (a list) gets the mask of pixels
    with a colour code at full scale appended."""
    mode = im.mode
    w, h = im.size
    factor = max(1, math.ceil(max(w, h) / MAX_WORK_SIDE))
    notes = []
    if factor > 1 and im.format == "JPEG":
        im.draft("RGB" if mode != "CMYK" else mode, (w // factor, h // factor))  # DCT scaling
        factor = max(1, math.ceil(max(im.size) / MAX_WORK_SIDE))
        notes.append(f"decoded at {im.size[0]}×{im.size[1]} (from {w}×{h})")
    if mode == "CMYK":
        im = im.convert("RGB")
        notes.append("CMYK converted to RGB (no colour profile applied)")
    elif mode in ("L", "P", "1"):
        has_alpha = mode == "P" and "transparency" in im.info
        im = im.convert("RGBA" if has_alpha else "RGB")
        notes.append(f"{'palette' if mode == 'P' else 'grayscale'} image converted to RGB")
    elif mode in ("LA", "PA"):
        im = im.convert("RGBA")
        notes.append("grayscale+alpha image converted to RGBA")
    elif mode in ("YCbCr", "LAB", "HSV"):
        im = im.convert("RGB")
        notes.append(f"{mode} image converted to RGB")
    codes = np.asarray(im)
    if codes.ndim == 2:  # 16/32-bit grayscale ("I;16", "I"): replicate to RGB
        codes = np.repeat(codes[..., None], 3, axis=-1)
        notes.append(f"{mode} grayscale image converted to RGB")
    if codes.dtype == np.uint8:
        levels = 256
    elif codes.dtype in (np.uint16, np.int32, np.uint32, np.dtype(">u2"), np.dtype("<u2")):
        codes = np.clip(codes, 0, 65535).astype(np.uint16)
        levels = 65536
    elif codes.dtype == np.bool_:
        codes = codes.astype(np.uint8) * 255
        levels = 256
    else:
        raise ImageInputError(f"{path}: unsupported pixel type {codes.dtype} (mode {mode})")
    if codes.shape[-1] not in (3, 4):
        raise ImageInputError(f"{path}: expected an RGB or RGBA image, got {codes.shape[-1]} channels "
                              f"(mode {mode})")
    out = _decode_downsampled(codes, levels, codes.shape[-1] == 4, factor, linear, saturated)
    if factor > 1:
        notes.append(f"downsampled {factor}× to {out.shape[1]}×{out.shape[0]}")
    if notes:
        warnings.warn(f"{path}: " + "; ".join(notes), ImageNote, stacklevel=3)
    return out


def clean_exr_pixels(arr: np.ndarray, path: str | Path) -> np.ndarray:
    """Refuse NaN/Inf pixel values of a linear image; clamp negative colour values to 0 with a
    warning. Both messages give the count."""
    colour = arr[..., :3]
    nan, inf = int(np.isnan(colour).sum()), int(np.isinf(colour).sum())
    if nan or inf:
        raise ImageInputError(f"{path}: image holds NaN or Inf values ({nan:,} NaN, {inf:,} infinite "
                              f"of {colour.size:,}); fix or re-export it")
    neg = int((colour < 0).sum())
    if neg:
        np.maximum(colour, 0.0, out=colour)
        warnings.warn(f"{path}: {neg:,} negative values (of {colour.size:,}) clamped to 0", ImageNote,
                      stacklevel=3)
    return arr


def downsample_linear(arr: np.ndarray) -> np.ndarray:
    """Box-average a linear float image (H, W, C) so its longer side is ≤ MAX_WORK_SIDE."""
    h, w = arr.shape[:2]
    factor = max(1, math.ceil(max(h, w) / MAX_WORK_SIDE))
    if factor == 1:
        return arr
    oh, ow = h // factor, w // factor
    return arr[:oh * factor, :ow * factor].reshape(oh, factor, ow, factor, -1).mean(axis=(1, 3)) \
        .astype(np.float32)
