"""The SpecGen network at CPU size: config, encoder, tri-planes, fusion, MLP, weights I/O.

``Config`` and ``DEFAULT_WEIGHTS`` import without torch (the onnxruntime path inside a stock
Blender needs them); the torch modules load on first use of the other names (PEP 562).
"""

from pathlib import Path

from .config import Config

DEFAULT_WEIGHTS = Path(__file__).resolve().parents[2] / "weights" / "specgen_default.pt"

_TORCH_NAMES = {"SpecGen", "count_parameters", "load_weights", "save_weights"}

__all__ = ["Config", "SpecGen", "DEFAULT_WEIGHTS", "count_parameters", "load_weights", "save_weights"]


def __getattr__(name: str):
    if name in _TORCH_NAMES:
        from . import specgen

        return getattr(specgen, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
