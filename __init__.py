"""SpecGen Blender extension: spectral BRDF from one sphere photo, rendered per band in Cycles.

One import scheme everywhere: the bpy-free core is always the top-level package
``specgen_addon`` (installed with ``pip install -e .``, or found beside this file), and the Blender
tier ``ops`` imports it by that name. Installed as an extension this folder is the package
``bl_ext.<repository>.specgen``, so it puts its own folder on ``sys.path`` for the core; tests and
``batch.py`` load this folder as the package ``specgen`` (:func:`batch.load_package`) for ``ops``.
A class of the core is therefore one object in every entry (CLI, batch.py, panel).
Nothing here imports ``bpy`` at module level: the core stays importable without Blender.
"""

import os
import sys

EXTENSION_ID = "specgen"

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.append(_HERE)


def register() -> None:
    """Register properties, operators and the 3D-viewport N-panel."""
    from .ops import register as _register

    _register()


def unregister() -> None:
    """Unregister everything :func:`register` added."""
    from .ops import unregister as _unregister

    _unregister()
