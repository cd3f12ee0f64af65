"""Blender side of SpecGen: scene settings, operators, the N-panel, the OSL bake and Cycles driver.

``register``/``unregister`` add and remove exactly the classes and the ``Scene.specgen`` property of
:mod:`.properties`, :mod:`.operators` and :mod:`.panel`; the numerics live in the bpy-free core
(:mod:`specgen_addon.bake.lookup`, :mod:`specgen_addon.bake.scene_uplift`, :mod:`specgen_addon.bake.closure_fit`)
and the core package.
"""

from __future__ import annotations

_MODULES = ("properties", "operators", "export_brdf", "circle_pick", "photo_panel", "panel", "travel")


def _modules():
    import importlib

    return [importlib.import_module(f"{__name__}.{name}") for name in _MODULES]


def register() -> None:
    for module in _modules():
        module.register()


def unregister() -> None:
    for module in reversed(_modules()):
        module.unregister()
