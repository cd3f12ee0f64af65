"""Fits of tabulated BRDFs to renderer-native closures (numpy only: runs inside Blender)."""

from .closures import ClosureFit, fit_closures, ggx_lobe, rgb_standin

__all__ = ["ClosureFit", "fit_closures", "ggx_lobe", "rgb_standin"]
