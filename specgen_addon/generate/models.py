"""What can make a BRDF from a photo: the one list that the command line's ``--model``, the
panel's *Model* menu and :func:`specgen_addon.generate.pipeline.generate` all read, so a new
way of generating is added here (and in the pipeline) without touching the Blender tier."""

from __future__ import annotations

from typing import NamedTuple


class ModelChoice(NamedTuple):
    """One way of generating: its label in the panel, one sentence on what it does, and whether
    its BRDF is then refined to the photo (the panel's *Refine to Photo*, ``--refine``)."""

    label: str
    description: str
    refines: bool


#: name → choice, in the order they are offered; the first is the default.
MODELS: dict[str, ModelChoice] = {
    "network": ModelChoice("SpecGen Network",
                           "the network's BRDF (SpecGen), then refined to the photo", refines=True),
    "thin-film": ModelChoice("Thin-Film Fit",
                             "fit the thin-film interference family (soap, oil, anodised metal) to "
                             "the photo, for a colour that changes with angle", refines=False),
}
DEFAULT_MODEL = next(iter(MODELS))
