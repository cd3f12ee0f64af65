"""Lighting assets: the CC0 HDR environment maps that ship inside the ``bpy`` wheel.

Blender's studio-light worlds (``studiolights/world/*.exr`` under Blender's ``datafiles``, Poly
Haven originals, CC0, 1024×512) are located at run time, never copied into the repository:

1. through Blender's own API, ``bpy.utils.system_resource('DATAFILES', path='studiolights/world')``,
   right in an installed Blender and in the bpy module alike — but only when ``bpy`` is already
   imported (this core never imports it);
2. else in the bpy *wheel*'s layout (``bpy/<version>/datafiles/...``), found with
   ``importlib.util.find_spec("bpy")`` without importing it.

Both steps are injectable (:func:`studiolights_dir` takes a resolver), so each layout is testable.

Split, after the paper's robustness table (one training indoor map, one held-out indoor map, one
held-out outdoor map): :data:`TRAIN_ENVS` light the training inputs (with rotations and exposures as
augmentation); :data:`HELDOUT_ENVS` are never used in training and serve as unseen lighting.
"""

from __future__ import annotations

import functools
import importlib.util
import sys
from pathlib import Path
from typing import Callable

from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.environment import Environment

#: Maps used for training inputs (``studio`` first: the canonical input's map).
TRAIN_ENVS: tuple[str, ...] = ("studio", "city", "forest", "sunrise", "sunset", "night")
#: Maps never seen in training: an outdoor one, then an indoor one.
HELDOUT_ENVS: tuple[str, ...] = ("courtyard", "interior")
_RELATIVE = Path("datafiles") / "studiolights" / "world"


class LightingAssetError(SpecGenError):
    """The environment maps of the bpy wheel cannot be found."""


def blender_datafiles_dir() -> Path | None:
    """``studiolights/world`` from Blender's API when ``bpy`` is already imported, else None."""
    bpy = sys.modules.get("bpy")
    utils = getattr(bpy, "utils", None)
    if utils is None or not hasattr(utils, "system_resource"):
        return None
    found = utils.system_resource("DATAFILES", path=_RELATIVE.relative_to("datafiles").as_posix())
    return Path(found) if found else None


def wheel_datafiles_dir() -> Path | None:
    """``datafiles/studiolights/world`` in the bpy wheel's layout (``bpy/<version>/...``), found
    without importing bpy; None when the wheel is not installed or has no such folder."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        # Once bpy is imported anywhere, its ``bpy/<version>/scripts/modules`` sits on sys.path (and a
        # spawned worker inherits it), so the spec may be that inner package: look up from it too.
        for base in (Path(root), *list(Path(root).parents)[:4]):
            for candidate in sorted(base.glob(f"*/{_RELATIVE.as_posix()}"), reverse=True):
                if candidate.is_dir():
                    return candidate
    return None


def studiolights_dir(resolvers: tuple[Callable[[], Path | None], ...] | None = None) -> Path:
    """Directory holding Blender's studio-light world EXRs.

    ``resolvers`` are tried in order (default: :func:`blender_datafiles_dir`, then
    :func:`wheel_datafiles_dir`); the first existing directory wins.
    """
    for resolve in resolvers or (blender_datafiles_dir, wheel_datafiles_dir):
        found = resolve()
        if found is not None and Path(found).is_dir():
            return Path(found)
    raise LightingAssetError("Blender's studio-light environment maps were not found (run inside "
                             "Blender, or install the bpy wheel: pip install bpy==5.0.1)")


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
