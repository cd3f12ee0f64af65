"""Training of SpecGen: data (targets + cached input renders) and the joint RGB/spectral loop.

:func:`build_material_sets` (:mod:`.material_sets`) assembles what
:func:`specgen_addon.train.loop.train` consumes; :mod:`.loop` runs it.
"""

from specgen_addon.train.loop import MaterialSet, TrainConfig
from specgen_addon.train.material_sets import SHARED_RGL_DIR, build_material_sets, render_input_variant
from specgen_addon.train.network_input import network_inputs, png_like

__all__ = ["SHARED_RGL_DIR", "MaterialSet", "TrainConfig", "build_material_sets", "network_inputs", "png_like",
           "render_input_variant"]
