"""Image files for the panel's path: OpenEXR (float channels + string attributes) and PNG/JPEG.

Two interchangeable backends, chosen per call, so one code path runs everywhere:

* the ``OpenEXR`` and ``Pillow`` packages when importable (CLI, training, tests);
* else OpenImageIO, which every Blender bundles (``bpy/<ver>/python/lib/python3.x/site-packages``
  in the bpy wheel; importable as ``OpenImageIO`` inside a real Blender), so a stock Blender
  reads the input photo and writes lookups and spectral EXRs with no extra wheel.

Writes are atomic (:func:`specgen_addon.common.atomic_io.atomic_write`). No ``bpy`` here.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.common.quiet import native_output_silenced


class ImageIOError(SpecGenError):
    """An image file cannot be read or written with any available backend."""


def _openexr():
    try:
        import OpenEXR
    except ImportError:
        return None
    return OpenEXR


def _pillow():
    try:
        from PIL import Image
    except ImportError:
        return None
    return Image


def _oiio():
    try:
        import OpenImageIO
    except ImportError:
        raise ImageIOError("neither OpenEXR/Pillow nor OpenImageIO (bundled with Blender) is "
                           "importable") from None
    return OpenImageIO


def write_exr(path: str | os.PathLike, channels: dict[str, np.ndarray], overwrite: bool = False,
              attributes: dict[str, str] | None = None, tiled: bool = False,
              compression: str = "zip") -> Path:
    """Write float32 channels (each H×W) and string header attributes as one OpenEXR part.

    ``tiled`` writes 64×64 tiles (OSL's texture cache reads them directly); ``compression`` is
    ``"zip"`` or ``"none"``.
    """
    planes = {str(k): np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    shapes = {p.shape for p in planes.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ImageIOError(f"{path}: EXR channels must share one H×W shape, got {sorted(shapes)}")
    attrs = {str(k): str(v) for k, v in (attributes or {}).items()}
    exr = _openexr()
    with atomic_write(path, overwrite=overwrite) as tmp:
        if exr is not None:
            header = {"compression": exr.ZIP_COMPRESSION if compression == "zip" else exr.NO_COMPRESSION,
                      "type": exr.scanlineimage}
            if tiled:
                tiles = exr.TileDescription()
                tiles.xSize = tiles.ySize = 64
                tiles.mode = exr.ONE_LEVEL
                header.update(type=exr.tiledimage, tiles=tiles)
            header.update(attrs)
            with exr.File(header, planes) as f:
                f.write(str(tmp))
        else:
            _write_exr_oiio(tmp, planes, attrs, tiled, compression)
    return Path(path)


def _write_exr_oiio(path: Path, planes: dict[str, np.ndarray], attrs: dict[str, str], tiled: bool,
                    compression: str) -> None:
    oiio = _oiio()
    names = list(planes)
    h, w = planes[names[0]].shape
    spec = oiio.ImageSpec(w, h, len(names), "float")
    spec.channelnames = tuple(names)
    spec.attribute("compression", "zip" if compression == "zip" else "none")
    if tiled:
        spec.tile_width = spec.tile_height = 64
    for key, value in attrs.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create("openexr")
    if out is None or not out.open(str(path), spec):
        raise ImageIOError(f"{path}: cannot write EXR ({oiio.geterror()})")
    try:
        if not out.write_image(np.stack([planes[n] for n in names], axis=-1)):
            raise ImageIOError(f"{path}: cannot write EXR ({out.geterror()})")
    finally:
        out.close()


def read_exr(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """(channels name → float32 H×W, string header attributes) of an EXR's first part."""
    path = Path(path)
    if not path.is_file():
        raise ImageIOError(f"{path}: no such file")
    exr = _openexr()
    try:
        with native_output_silenced():   # the readers' own lines about a damaged file
            if exr is not None:
                with exr.File(str(path), separate_channels=True) as f:
                    part = f.parts[0]
                    header = {k: v for k, v in part.header.items() if isinstance(v, str)}
                    return ({n: np.asarray(c.pixels, dtype=np.float32) for n, c in part.channels.items()},
                            header)
            oiio = _oiio()
            inp = oiio.ImageInput.open(str(path))
            if inp is None:
                raise ImageIOError(oiio.geterror())
            try:
                spec = inp.spec()
                pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
            finally:
                inp.close()
            if pixels is None:
                raise ImageIOError(oiio.geterror())
        data = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
        header = {p.name: p.value for p in spec.extra_attribs if isinstance(p.value, str)}
        return {n: np.ascontiguousarray(data[..., i]) for i, n in enumerate(spec.channelnames)}, header
    except Exception as exc:  # the bindings raise plain RuntimeError/ValueError on corrupt files
        raise ImageIOError(f"{path}: not a readable OpenEXR file ({_reason(exc)})") from None


def _reason(problem: BaseException | str) -> str:
    """A reader's complaint about a damaged file (an exception, or the text OpenImageIO keeps), as
    a clause: its first line, or what an indexing error in the bindings means (a file cut short)."""
    if isinstance(problem, (IndexError, KeyError)):
        return "damaged or cut short"
    first = next((line.strip() for line in str(problem).splitlines() if line.strip()), "")
    return first.removesuffix(".") or "damaged or cut short"


def read_ldr(path: str | os.PathLike) -> np.ndarray:
    """An 8/16-bit PNG/JPEG/TIFF as float32 (H, W, C) in [0, 1], values as stored (no decoding)."""
    path = Path(path)
    if not path.is_file():
        raise ImageIOError(f"{path}: no such image file")
    image = _pillow()
    if image is not None:
        try:
            with image.open(path) as im:
                mode = im.mode
                arr = np.asarray(im)
        except OSError as exc:  # UnidentifiedImageError is an OSError
            raise ImageIOError(f"{path}: cannot read image ({exc})") from None
        if arr.dtype == np.uint8:
            arr = arr.astype(np.float32) / 255.0
        elif arr.dtype in (np.uint16, np.int32) or mode.startswith("I;16"):
            arr = arr.astype(np.float32) / 65535.0
        else:
            arr = arr.astype(np.float32)
        return arr[..., None] if arr.ndim == 2 else arr
    _oiio()
    return read_float_image(path, ImageIOError)


def read_float_image(path: str | os.PathLike, error: type[SpecGenError] = ImageIOError,
                     what: str = "image") -> np.ndarray:
    """Every channel of an image file as float32 (H, W, C), row 0 on top, integers normalised to
    [0, 1], via OpenImageIO (bundled with Blender, so this also works inside a stock Blender).

    Whatever fails raises the caller's ``error`` (a :class:`SpecGenError` subclass) with one
    sentence naming ``path``; ``what`` names the kind of file in it ("image", "Radiance HDR").
    """
    path = Path(path)
    try:
        import OpenImageIO as oiio
    except ImportError:
        raise error(f"{path}: reading {path.suffix} files needs OpenImageIO (bundled with Blender)") from None
    with native_output_silenced():   # the readers' own lines about a damaged file
        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            raise error(f"{path}: cannot read {what} ({_reason(oiio.geterror())})")
        try:
            spec = inp.spec()
            data = inp.read_image(0, 0, 0, spec.nchannels, "float")  # integers normalised to [0, 1]
        finally:
            inp.close()
    if data is None:
        raise error(f"{path}: cannot read {what} ({_reason(oiio.geterror())})")
    return np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)


def write_png8(path: str | os.PathLike, pixels: np.ndarray, overwrite: bool = False) -> Path:
    """Write uint8 pixels (H, W, 3|4) as a PNG, atomically."""
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    image = _pillow()
    with atomic_write(path, overwrite=overwrite) as tmp:
        if image is not None:
            image.fromarray(pixels).save(tmp, format="PNG")
        else:
            oiio = _oiio()
            h, w, c = pixels.shape
            out = oiio.ImageOutput.create("png")
            if out is None or not out.open(str(tmp), oiio.ImageSpec(w, h, c, "uint8")):
                raise ImageIOError(f"{path}: cannot write PNG ({oiio.geterror()})")
            try:
                out.write_image(pixels)
            finally:
                out.close()
    return Path(path)
