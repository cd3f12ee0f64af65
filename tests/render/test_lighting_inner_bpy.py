"""The bundled maps are found when ``find_spec('bpy')`` answers with bpy's inner Python package
(``bpy/<version>/scripts/modules/bpy``), as it does in a worker spawned after bpy was imported."""

from __future__ import annotations

import importlib.machinery
from pathlib import Path

import pytest

from specgen_addon.render import environment_maps as lighting


def test_maps_are_found_from_bpys_inner_scripts_package(monkeypatch):
    wheel = lighting.wheel_datafiles_dir()
    if wheel is None:
        pytest.skip("the bpy wheel is not installed")
    inner = sorted(Path(wheel).parents[2].glob("scripts/modules/bpy"))
    if not inner:
        pytest.skip("this bpy wheel has no scripts/modules/bpy package")
    spec = importlib.machinery.ModuleSpec("bpy", None, is_package=True)
    spec.submodule_search_locations = [str(inner[0])]
    monkeypatch.setattr(lighting.importlib.util, "find_spec", lambda name: spec)
    assert lighting.wheel_datafiles_dir() == wheel
