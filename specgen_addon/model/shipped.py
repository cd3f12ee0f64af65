"""The shipped networks' files (docs/model-card.md), named without torch: the onnxruntime path
inside a stock Blender needs them."""

from __future__ import annotations

from pathlib import Path

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
