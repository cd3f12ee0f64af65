"""Shared fixtures. ``shared_dir`` points at ../shared beside the repo and skips when absent."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def repo_dir() -> Path:
    return REPO


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """The project's ../shared folder (real RGL files); tests using it skip on a user's clone."""
    if not (SHARED / "data" / "rgl").is_dir():
        pytest.skip(f"needs ../shared/data/rgl beside the repo (not found at {SHARED}); "
                    "it holds the real RGL measurements used for checks")
    return SHARED


@pytest.fixture(scope="session")
def rgl_files(shared_dir: Path) -> dict[str, Path]:
    """The real RGL RGB files by short name: ``felt`` and ``metallic``."""
    d = shared_dir / "data" / "rgl"
    return {"felt": d / "acrylic_felt_green_rgb.bsdf", "metallic": d / "ilm_l3_37_metallic_rgb.bsdf"}


@pytest.fixture
def blank_scene():
    """The scene of an empty .blend (Blender's factory settings, no objects), so no object, panel
    value or handler of an earlier test is left; skips without the bpy module."""
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene
