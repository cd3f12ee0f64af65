"""Fits of tabulated BRDFs to renderer-native closures (numpy only: runs inside Blender)."""

from .closures import (ClosureFit, StackClosure, fit_closures, ggx_lobe, group_closures, rgb_standin,
                       stack_layout, standin_closures)

__all__ = ["ClosureFit", "StackClosure", "fit_closures", "ggx_lobe", "group_closures", "rgb_standin",
           "stack_layout", "standin_closures"]
