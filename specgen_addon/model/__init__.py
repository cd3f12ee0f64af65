"""The SpecGen network at CPU size: config, encoder, tri-planes, fusion, MLP, weights I/O.

``Config`` and ``DEFAULT_WEIGHTS`` import without torch (the onnxruntime path inside a stock
Blender needs them); the torch names (``SpecGen``, ``count_parameters``, ``load_weights``,
``save_weights``, from :mod:`.specgen`) load on first use (PEP 562).
"""

from specgen_addon.model.config import Config
from specgen_addon.model.shipped import DEFAULT_WEIGHTS, RESAMPLED_WEIGHTS, shipped_weights

__all__ = ["Config", "SpecGen", "DEFAULT_WEIGHTS", "RESAMPLED_WEIGHTS", "shipped_weights", "count_parameters",
           "load_weights", "save_weights"]


def __getattr__(name: str):
    if name in ("SpecGen", "count_parameters", "load_weights", "save_weights"):
        from specgen_addon.model import specgen

        return getattr(specgen, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
