"""bench/ and scripts/ files loaded as modules in a test, the way they load when run.

A script run as ``python bench/x.py`` finds its sibling modules (``from machine import …``)
because its own folder is the first entry of the import path; loaded here it gets the same. This
is the one place outside the entry scripts and child-process sources that changes ``sys.path``.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[1]


def load_script(relative_path: str) -> ModuleType:
    """The script at ``relative_path`` (from the repository root) as a module named after it."""
    path = REPO / relative_path
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    if path.stem in sys.modules:
        return sys.modules[path.stem]
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module
    spec.loader.exec_module(module)
    return module
