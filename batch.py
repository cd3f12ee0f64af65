"""Headless SpecGen: image of a sphere -> spectral BRDF -> spectral EXR render (placeholder)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent
PACKAGE = "specgen"


def load_package(name: str = PACKAGE):
    """Import this repository as the package ``name`` (as Blender imports the installed extension,
    ``bl_ext.<repo>.specgen``), so ``ops`` reaches the core with the same relative imports."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, REPO / "__init__.py",
                                                  submodule_search_locations=[str(REPO)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
