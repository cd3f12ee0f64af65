"""Lighting assets: the CC0 HDR environment maps that ship inside the ``bpy`` wheel.

Blender's studio-light worlds (``bpy/<version>/datafiles/studiolights/world/*.exr``, Poly Haven
originals, CC0, 1024×512) are located at run time through ``importlib.util.find_spec("bpy")`` —
``bpy`` is never imported and nothing is copied into the repository.

Split, after the paper's robustness table (one training indoor map, one held-out indoor map, one
held-out outdoor map): :data:`TRAIN_ENVS` light the training inputs (with rotations and exposures as
augmentation); :data:`HELDOUT_ENVS` are never used in training and serve as unseen lighting.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

from .errors import SpecGenError
from .render.environment import Environment

#: Maps used for training inputs (``studio`` first: the canonical input's map).
TRAIN_ENVS: tuple[str, ...] = ("studio", "city", "forest", "sunrise", "sunset", "night")
#: Maps never seen in training: an outdoor one, then an indoor one.
HELDOUT_ENVS: tuple[str, ...] = ("courtyard", "interior")
_RELATIVE = Path("datafiles") / "studiolights" / "world"


class LightingAssetError(SpecGenError):
    """The environment maps of the bpy wheel cannot be found."""


def studiolights_dir() -> Path:
    """Directory holding Blender's studio-light world EXRs (located without importing bpy)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise LightingAssetError("environment maps come from the bpy wheel, which is not installed "
                                 "(pip install bpy==5.0.1)")
    for root in spec.submodule_search_locations:
        for candidate in sorted(Path(root).glob(f"*/{_RELATIVE.as_posix()}"), reverse=True):
            if candidate.is_dir():
                return candidate
    raise LightingAssetError(f"bpy is installed but has no {_RELATIVE.as_posix()} directory "
                             f"under {list(spec.submodule_search_locations)}")


def available_envs() -> list[str]:
    """Names (file stems) of every environment map in the wheel."""
    return sorted(p.stem for p in studiolights_dir().glob("*.exr"))


def env_path(name: str) -> Path:
    """Path of the environment map called ``name`` (e.g. ``"studio"``)."""
    path = studiolights_dir() / f"{name}.exr"
    if not path.is_file():
        raise LightingAssetError(f"no environment map named {name!r}; available: "
                                 f"{', '.join(available_envs())}")
    return path


def load_environment(name: str, exposure: float = 1.0, rotation_rad: float = 0.0) -> Environment:
    """Environment map ``name`` normalised to unit mean luminance, times ``exposure``, rotated about
    the up axis by ``rotation_rad`` (see :meth:`Environment.from_file`).

    Loaded maps are cached with their sampling and irradiance tables: treat them as read-only
    (``Environment.with_`` makes a modified copy).
    """
    return _load_cached(name, float(exposure), float(rotation_rad))


@functools.lru_cache(maxsize=16)
def _load_cached(name: str, exposure: float, rotation_rad: float) -> Environment:
    return Environment.from_file(env_path(name), exposure=exposure, rotation_rad=rotation_rad)
