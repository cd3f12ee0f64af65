"""Studio-light HDRIs are found through Blender's API in an installed Blender's layout, and in the
bpy wheel's layout when bpy is not imported; the core never imports bpy for it."""

from __future__ import annotations

import sys
import types
from pathlib import Path

import pytest

from specgen_addon.render import environment_maps as lighting


def _installed_blender(tmp_path: Path) -> tuple[types.ModuleType, Path]:
    """A stand-in ``bpy`` whose system_resource answers like Blender 4.2 installed in /opt."""
    world = tmp_path / "blender-4.2.0-linux-x64" / "4.2" / "datafiles" / "studiolights" / "world"
    world.mkdir(parents=True)
    (world / "forest.exr").write_bytes(b"")
    calls = []

    def system_resource(kind, path=""):
        calls.append((kind, path))
        full = world.parent.parent / path
        return str(full) if kind == "DATAFILES" and full.is_dir() else ""

    fake = types.ModuleType("bpy")
    fake.utils = types.SimpleNamespace(system_resource=system_resource)
    fake.calls = calls
    return fake, world


def test_studio_lights_come_from_blenders_api_in_an_installed_layout(tmp_path, monkeypatch):
    fake, world = _installed_blender(tmp_path)
    monkeypatch.setitem(sys.modules, "bpy", fake)
    assert lighting.studiolights_dir() == world
    assert fake.calls == [("DATAFILES", "studiolights/world")]
    assert lighting.available_envs() == ["forest"]


def test_studio_lights_fall_back_to_the_wheel_layout_without_blenders_api(monkeypatch):
    wheel = lighting.wheel_datafiles_dir()   # located with find_spec, never importing bpy
    if wheel is None:
        pytest.skip("the bpy wheel is not installed")
    assert wheel.parent.parent.name == "datafiles" and wheel.parents[3].name == "bpy"
    monkeypatch.setattr(lighting, "blender_datafiles_dir", lambda: None)  # bpy not imported
    found = lighting.studiolights_dir()
    assert found == wheel and (found / "studio.exr").is_file()


def test_blenders_api_is_asked_only_when_bpy_is_already_imported(monkeypatch):
    monkeypatch.setitem(sys.modules, "bpy", None)   # as if never imported
    assert lighting.blender_datafiles_dir() is None


def test_blenders_api_and_the_wheel_layout_agree_in_the_bpy_module():
    bpy = pytest.importorskip("bpy")
    api = lighting.blender_datafiles_dir()
    assert api is not None and sys.modules["bpy"] is bpy
    assert api.resolve() == lighting.wheel_datafiles_dir().resolve()


def test_missing_studio_lights_is_one_clear_error():
    with pytest.raises(lighting.LightingAssetError, match="not found"):
        lighting.studiolights_dir((lambda: None, lambda: None))
