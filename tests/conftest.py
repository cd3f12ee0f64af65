"""Shared fixtures: the repository and ../shared folders, real RGL files, a fresh .blend with the
add-on registered, a numpy-only Python runner, the tiny network, a tiny corpus and a tiny spectral table.

Helper modules beside this file (tiny_model, tiny_training, numpy_only, addon_modules,
batch_stand_in, specgen_standins) are importable by name from every test folder.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from numpy_only import run_numpy_only
from specgen_standins import RampMaterial
from tiny_model import TINY_MODEL

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"

#: Wavelengths (nm) of the tiny spectral table :func:`ramp_table`.
RAMP_WL = np.linspace(380.0, 780.0, 9)


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


# ------------------------------------------------------------------------------ Blender tier
@pytest.fixture
def blank_scene():
    """The scene of an empty .blend (Blender's factory settings, no objects), so no object, panel
    value or handler of an earlier test is left; skips without the bpy module."""
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


@pytest.fixture
def registered_addon(blank_scene):
    """An empty .blend with the add-on registered (``scene.specgen``, the operators and the panel),
    unregistered afterwards; gives the scene. Skips without the bpy module."""
    from addon_modules import PKG  # needs bpy: imported only once the skip above has passed

    PKG.register()
    try:
        yield blank_scene
    finally:
        PKG.unregister()


@pytest.fixture(scope="session")
def default_weights() -> Path:
    """The shipped default network; tests that run it skip where it has not been built yet."""
    from specgen_addon.model import DEFAULT_WEIGHTS

    if not Path(DEFAULT_WEIGHTS).is_file():
        pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
    return Path(DEFAULT_WEIGHTS)


@pytest.fixture
def sphere_photo(tmp_path: Path) -> Path:
    """A 64 px PNG of a grey Lambertian sphere lit from the camera, as Generate takes it."""
    from PIL import Image

    from specgen_addon.render import DistantLight, render_spectral, sphere_geometry
    from specgen_addon.render.analytic import Lambertian

    img = render_spectral(Lambertian(albedo=0.5), sphere_geometry(64), lights=[DistantLight((0, 0, 1))],
                          wavelengths_nm=np.array([450.0, 550.0, 650.0])).spectral
    rgb = np.clip(np.repeat(img.mean(-1, keepdims=True), 3, -1), 0, 1)
    path = tmp_path / "sphere.png"
    Image.fromarray((rgb * 255).astype(np.uint8)).save(path)
    return path


# ------------------------------------------------------------------------------- core set-up
@pytest.fixture(scope="session")
def numpy_only() -> Callable[..., subprocess.CompletedProcess]:
    """``numpy_only(body, timeout=300)``: run dedented Python in a child process where only numpy
    and the standard library import (the panel's path in a stock Blender)."""
    return lambda body, timeout=300: run_numpy_only(REPO, body, timeout=timeout)


@pytest.fixture(scope="session")
def ramp_table():
    """A small 9-band table of the analytic ramp material (diffuse + GGX), 380-780 nm."""
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable

    mat = RampMaterial(a=0.3, b=0.3, alpha=0.2, f0=0.05)

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return mat.eval(wi, wo, RAMP_WL)

    return BRDFTable.tabulate(fn, RAMP_WL)


@pytest.fixture(scope="session")
def tiny_config():
    """:class:`specgen_addon.model.Config` of the tiny network (:data:`tiny_model.TINY_MODEL`)."""
    from specgen_addon.model import Config  # torch: only for the tests that ask

    return Config(**TINY_MODEL)


@pytest.fixture(scope="session")
def tiny_network():
    """``tiny_network(**changes)``: a freshly seeded (seed 0) tiny SpecGen network; ``changes``
    are Config fields over :data:`tiny_model.TINY_MODEL`."""
    import torch

    from specgen_addon.model import Config, SpecGen

    def make(**changes):
        torch.manual_seed(0)
        return SpecGen(Config(**{**TINY_MODEL, **changes}))

    return make


@pytest.fixture(scope="session")
def tiny_corpus() -> tuple:
    """The first 60 materials of the mixed corpus, seed 0 (every family, some of each split)."""
    from specgen_addon.corpus.generate import generate_mixed_corpus

    return tuple(generate_mixed_corpus(60, 0))
