"""Fits of tabulated BRDFs to renderer-native closures (numpy only: runs inside Blender)."""

from specgen_addon.bake.closure_fit.closures import (ClosureFit, StackClosure, fit_closures, ggx_lobe, group_closures, rgb_standin,
                       stack_layout, standin_closures)

__all__ = ["ClosureFit", "StackClosure", "fit_closures", "ggx_lobe", "group_closures", "rgb_standin",
           "stack_layout", "standin_closures"]
