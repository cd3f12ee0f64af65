"""The SpecGen network at CPU size: config, encoder, tri-planes, fusion, MLP, weights I/O."""

from .config import Config
from .specgen import DEFAULT_WEIGHTS, SpecGen, count_parameters, load_weights, save_weights

__all__ = ["Config", "SpecGen", "DEFAULT_WEIGHTS", "count_parameters", "load_weights", "save_weights"]
