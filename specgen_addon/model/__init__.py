"""The SpecGen network at CPU size: config, encoder, tri-planes, fusion, MLP, weights I/O.

``Config`` and ``DEFAULT_WEIGHTS`` import without torch (the onnxruntime path inside a stock
Blender needs them); the torch modules load on first use of the other names (PEP 562).
"""

from pathlib import Path

from specgen_addon.model.config import Config

#: The shipped network for a sphere copied pixel for pixel from a canonical frame (the test split's
#: inputs, renders framed on whole pixels).
DEFAULT_WEIGHTS = Path(__file__).resolve().parents[2] / "weights" / "specgen_default.pt"
#: The shipped network for a sphere resampled from a photo (off the pixel grid, antialiased, another
#: size: every camera photo), trained on such inputs only (docs/model-card.md).
RESAMPLED_WEIGHTS = DEFAULT_WEIGHTS.with_name("specgen_resampled.pt")


def shipped_weights(copied: bool) -> Path:
    """The shipped network for an input cut by :func:`specgen_addon.photo.sphere_image.crop_sphere`:
    :data:`DEFAULT_WEIGHTS` when its sphere was ``copied``, else :data:`RESAMPLED_WEIGHTS`."""
    return DEFAULT_WEIGHTS if copied else RESAMPLED_WEIGHTS

_TORCH_NAMES = {"SpecGen", "count_parameters", "load_weights", "save_weights"}

__all__ = ["Config", "SpecGen", "DEFAULT_WEIGHTS", "RESAMPLED_WEIGHTS", "shipped_weights", "count_parameters",
           "load_weights", "save_weights"]


def __getattr__(name: str):
    if name in _TORCH_NAMES:
        from specgen_addon.model import specgen

        return getattr(specgen, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
