"""SpecGen Blender extension: spectral BRDF from one sphere photo, rendered per band in Cycles.

Installed as an extension this folder is the package ``bl_ext.<repository>.specgen``; its
subpackages ``specgen_addon`` (bpy-free core) and ``ops`` (the Blender side) are reached with
relative imports only. Tests and ``batch.py`` load this folder under the package name ``specgen``
the same way (:func:`batch.load_package`), so there is one import scheme everywhere.
Nothing here imports ``bpy`` at module level: the core stays importable without Blender.
"""

EXTENSION_ID = "specgen"


def register() -> None:
    """Register properties, operators and the 3D-viewport N-panel."""
    from .ops import register as _register

    _register()


def unregister() -> None:
    """Unregister everything :func:`register` added."""
    from .ops import unregister as _unregister

    _unregister()
