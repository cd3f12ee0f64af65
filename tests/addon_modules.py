"""The add-on's modules as Blender imports them, for the headless bpy tests.

The repository is loaded as one package (:func:`batch.load_package`) for ``ops``, as an installed
extension is imported as ``bl_ext.<repo>.specgen``; the core is the top-level ``specgen_addon`` in
both cases, so ``addon_module("specgen_addon.common.errors")`` is ``specgen_addon.common.errors`` itself.
Import this module after ``pytest.importorskip("bpy")``.
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType

import numpy as np

import batch

PKG = batch.load_package()


def addon_module(dotted: str) -> ModuleType:
    """``addon_module("ops.render")``: that module of the loaded add-on package (the core,
    ``specgen_addon``, is one package for every entry)."""
    if dotted.split(".")[0] == "specgen_addon":
        return import_module(dotted)
    return import_module(f"{PKG.__name__}.{dotted}")


def psnr(a: np.ndarray, ref: np.ndarray) -> float:
    """PSNR (dB) of ``a`` against ``ref`` with the reference's maximum as the peak."""
    return float(10 * np.log10(ref.max() ** 2 / np.mean((a - ref) ** 2)))
