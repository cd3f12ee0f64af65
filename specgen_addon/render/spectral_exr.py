"""Spectral OpenEXR I/O in the layout of Fichet, Pacanowski & Wilkie (2021).

"An OpenEXR Layout for Spectral Images", JCGT 10(3), 2021. An emissive spectral image stores one
float channel per wavelength, named ``S0.<λ>nm`` with a comma as decimal separator (for example
``S0.550,000000nm``), and declares the layout in the header: ``spectralLayoutVersion = "1.0"`` and
``emissiveUnits = "W.m^-2.sr^-1"``. An RGB preview (``R``, ``G``, ``B``; linear sRGB, obtained by
integrating the spectrum against the CIE 1931 2° CMFs) sits beside the spectral channels so that
ordinary viewers show a picture.

numpy + :mod:`specgen_addon.common.image_io` (the ``OpenEXR`` package, or Blender's bundled OpenImageIO
when it is absent); no ``bpy``. Writes are atomic
(:func:`specgen_addon.common.atomic_io.atomic_write`) and never overwrite unless asked.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.image_io import ImageIOError, read_exr, write_exr, write_png8
from specgen_addon.spectral.spectra import spectral_to_linear_srgb, srgb_encode

SPECTRAL_LAYOUT_VERSION = "1.0"
EMISSIVE_UNITS = "W.m^-2.sr^-1"
_CHANNEL_RE = re.compile(r"^S0\.(\d+(?:,\d*)?)nm$")


class SpectralEXRError(SpecGenError):
    """A file is not a readable emissive spectral EXR in the Fichet et al. (2021) layout."""


@dataclass
class SpectralImage:
    """An emissive spectral image: radiance ``values`` (H, W, Λ) at ``wavelengths_nm`` (Λ,).

    ``rgb`` is the linear-sRGB preview (H, W, 3) when present; ``header`` holds the string
    attributes of the file (layout version, units, SpecGen metadata).
    """

    values: np.ndarray
    wavelengths_nm: np.ndarray
    rgb: np.ndarray | None = None
    header: dict[str, str] = field(default_factory=dict)


def channel_name(wavelength_nm: float) -> str:
    """Emissive channel name of one wavelength, e.g. ``550.0 -> "S0.550,000000nm"``."""
    return "S0." + f"{float(wavelength_nm):.6f}".replace(".", ",") + "nm"


def parse_channel_name(name: str) -> float | None:
    """Wavelength in nm of an ``S0.<λ>nm`` channel name, or ``None`` for any other channel."""
    match = _CHANNEL_RE.match(name)
    return None if match is None else float(match.group(1).replace(",", "."))


def linear_srgb_preview(values: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """CMF-integrated linear sRGB of a spectral image (H, W, Λ) -> (H, W, 3), float32."""
    return np.asarray(spectral_to_linear_srgb(values, wavelengths_nm), dtype=np.float32)


def write_spectral_exr(path: str | os.PathLike, values: np.ndarray, wavelengths_nm: np.ndarray,
                       overwrite: bool = False, rgb: np.ndarray | None = None,
                       attributes: dict[str, str] | None = None,
                       alpha: np.ndarray | None = None) -> Path:
    """Write an emissive spectral EXR (Fichet et al. 2021) with an RGB preview, atomically.

    Parameters
    ----------
    path
        Target ``.exr`` file.
    values
        Spectral radiance, shape (H, W, Λ), in W·m⁻²·sr⁻¹·nm⁻¹ (relative units are fine).
    wavelengths_nm
        Band centres in nanometres, shape (Λ,), strictly increasing.
    overwrite
        Replace an existing file; otherwise :class:`~specgen_addon.common.errors.OutputExistsError`.
    rgb
        Linear-sRGB preview (H, W, 3); computed from the spectrum with the CIE 1931 CMFs if omitted.
    attributes
        Extra string header attributes (e.g. the source image, the BRDF name).
    alpha
        Optional coverage (H, W) written as channel ``A`` (e.g. a render with a transparent film).

    Returns
    -------
    Path
        The written file.
    """
    values = np.asarray(values, dtype=np.float32)
    wavelengths = np.asarray(wavelengths_nm, dtype=np.float64).reshape(-1)
    if values.ndim != 3 or values.shape[2] != wavelengths.size:
        raise SpectralEXRError(f"{path}: values must be (H, W, {wavelengths.size}), got {values.shape}")
    if wavelengths.size > 1 and np.any(np.diff(wavelengths) <= 0):
        raise SpectralEXRError(f"{path}: wavelengths must be strictly increasing")
    if len({channel_name(w) for w in wavelengths}) != wavelengths.size:
        raise SpectralEXRError(f"{path}: wavelengths collide at 1e-6 nm precision")
    if rgb is None:
        rgb = linear_srgb_preview(values, wavelengths)
    rgb = np.asarray(rgb, dtype=np.float32)
    if rgb.shape != values.shape[:2] + (3,):
        raise SpectralEXRError(f"{path}: rgb preview must be {values.shape[:2] + (3,)}, got {rgb.shape}")

    channels = {channel_name(w): np.ascontiguousarray(values[:, :, i]) for i, w in enumerate(wavelengths)}
    for i, name in enumerate("RGB"):
        channels[name] = np.ascontiguousarray(rgb[:, :, i])
    if alpha is not None:
        if np.shape(alpha) != values.shape[:2]:
            raise SpectralEXRError(f"{path}: alpha must be {values.shape[:2]}, got {np.shape(alpha)}")
        channels["A"] = np.ascontiguousarray(alpha, dtype=np.float32)
    header = {"spectralLayoutVersion": SPECTRAL_LAYOUT_VERSION, "emissiveUnits": EMISSIVE_UNITS}
    for key, value in (attributes or {}).items():
        header[str(key)] = str(value)
    return write_exr(path, channels, overwrite=overwrite, attributes=header)


def read_spectral_exr(path: str | os.PathLike) -> SpectralImage:
    """Read an emissive spectral EXR written in the Fichet et al. (2021) layout.

    Raises :class:`SpectralEXRError` when the file is missing, unreadable, has no ``S0.<λ>nm``
    channel, or lacks the ``spectralLayoutVersion`` attribute.
    """
    path = Path(path)
    if not path.is_file():
        raise SpectralEXRError(f"{path}: no such file")
    try:
        raw, header = read_exr(path)
    except ImageIOError as exc:
        raise SpectralEXRError(str(exc)) from None
    if "spectralLayoutVersion" not in header:
        raise SpectralEXRError(f"{path}: missing spectralLayoutVersion attribute (not a spectral EXR)")
    bands = sorted((w, name) for name in raw if (w := parse_channel_name(name)) is not None)
    if not bands:
        raise SpectralEXRError(f"{path}: no emissive S0.<wavelength>nm channels")
    values = np.stack([raw[name] for _, name in bands], axis=-1)
    rgb = np.stack([raw[c] for c in "RGB"], axis=-1) if all(c in raw for c in "RGB") else None
    return SpectralImage(values=values, wavelengths_nm=np.array([w for w, _ in bands]), rgb=rgb,
                         header=header)


def write_preview_png(path: str | os.PathLike, rgb_linear: np.ndarray, overwrite: bool = False,
                      exposure: float = 1.0,
                      view: Callable[[np.ndarray], np.ndarray] | None = None) -> Path:
    """Write a linear-sRGB image (H, W, 3) as an 8-bit PNG, atomically: through ``view`` (scene
    linear -> display values in [0, 1], e.g. Blender's view transform from
    :mod:`specgen_addon.render.view_transform`) when given, else the plain sRGB transfer curve."""
    scaled = np.asarray(rgb_linear, dtype=np.float64) * exposure
    encoded = srgb_encode(np.clip(scaled, 0.0, 1.0)) if view is None else view(scaled)
    pixels = np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)
    return write_png8(path, pixels, overwrite=overwrite)
