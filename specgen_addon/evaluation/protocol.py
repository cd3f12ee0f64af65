"""The evaluation protocol (paper §4.1, §4.3): test materials, scenes, shapes and wavelengths.

Every comparison renders a *scene* (a shape under a lighting) three ways, all with the reference
renderer (:mod:`specgen_addon.render`) and the same sampling seed:

* ground truth: the test material's analytic spectral BRDF;
* SpecGen: the spectral BRDF generated from the material's *canonical sphere input image*
  (:mod:`specgen_addon.photo.sphere_image`), tabulated and rendered in the scene;
* baselines: the linear-sRGB render of the same scene uplifted pixel by pixel
  (:mod:`.baselines`).

Scenes (:func:`scene_list`): the sphere under distant lights, the sphere under three environment
maps (one from the training set, two held out, :mod:`specgen_addon.render.environment_maps`), and a second shape,
Blender's Suzanne, under a held-out environment and under the distant lights (the paper's bunny
experiment). The Suzanne normal map is captured once with Blender (``ops/normal_map.py`` run in a
subprocess with the ``bpy`` module) and cached; without ``bpy`` an analytic superellipsoid stands in
(and the report says so).
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from specgen_addon.spectral import spectra
from specgen_addon.common.errors import SpecGenError
from specgen_addon.render import DistantLight, Environment, Geometry, sphere_geometry
from specgen_addon.common.cache import cache_root
from specgen_addon.corpus import generate_corpus
from specgen_addon.photo import sphere_image as input_image
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.render import environment_maps as lighting
from specgen_addon.render.geometry import pixel_grid

#: Evaluation bands: 20 wavelengths, 400–780 nm in 20 nm steps (paper Table 2 uses 20).
WAVELENGTHS_NM = spectra.wavelength_grid(400.0, 780.0, 20)
#: Seven bands shown side by side in the GT-vs-prediction figure (paper Fig. 4).
FIGURE_WAVELENGTHS_NM = (420.0, 480.0, 540.0, 600.0, 640.0, 700.0, 760.0)
#: The corpus the default model trains on, and the one the test materials come from.
CORPUS_SIZE = 200
CORPUS_SEED = 0

#: Distant lights of the "distant light" scenes: a D65 key light from the upper left and a
#: weaker fill from the right (irradiance in the renderer's relative units, π = unit radiance).
DISTANT_LIGHTS = (
    DistantLight(direction=(-0.45, 0.55, 0.70), irradiance=float(np.pi) * 0.9, illuminant="D65"),
    DistantLight(direction=(0.75, -0.10, 0.65), irradiance=float(np.pi) * 0.35, illuminant="D65"),
)

SPHERE = "sphere"
SUZANNE = "suzanne"


@dataclass(frozen=True)
class Scene:
    """A shape under a lighting. ``env`` names an environment map (None: the distant lights)."""

    shape: str
    env: str | None = None
    seen_in_training: bool | None = None

    @property
    def name(self) -> str:
        return f"{self.shape}/{'distant' if self.env is None else 'env-' + self.env}"

    @property
    def lighting_label(self) -> str:
        if self.env is None:
            return "distant lights"
        return f"env. map '{self.env}' ({'seen' if self.seen_in_training else 'unseen'} in training)"


@dataclass(frozen=True)
class EnvChoice:
    """The three environment maps of the robustness table: one seen in training, two unseen."""

    seen: str
    unseen: tuple[str, str]


def env_choice() -> EnvChoice:
    """The map of training input variant 1 (every training run with ≥ 2 input variants sees it;
    variant 0 is the canonical input's own map) and the two held-out maps of
    :mod:`specgen_addon.render.environment_maps` (outdoor, indoor)."""
    held = list(lighting.HELDOUT_ENVS)
    if len(held) < 2:
        raise SpecGenError("the evaluation needs two held-out environment maps")
    return EnvChoice(input_image.training_variant(1)[0], (held[0], held[1]))


def input_lighting_under(env: str):
    """The :class:`~specgen_addon.photo.photo_lighting.InputLighting` of :func:`input_under_environment`:
    map ``env`` (unit mean luminance, unrotated) plus the canonical key light. A score of a table
    against such a photo renders it in this same lighting."""
    return InputLighting(env, key_light=True)


def input_under_environment(brdf, env: str, independent: bool = False) -> np.ndarray:
    """The sphere input image of ``brdf`` photographed under environment map ``env`` instead of the
    canonical one: same geometry, key light, exposure and sampling as
    :func:`specgen_addon.photo.sphere_image.render_input` (linear sRGB, float32); with ``independent``
    rendered with :func:`specgen_addon.photo.sphere_image.independent_sampling` instead, as a photograph
    shares no samples with the refinement's operator."""
    light = input_lighting_under(env)
    scene = light.scene(input_image.CANONICAL_SIZE)
    if independent:
        scene = input_image.with_independent_sampling(scene)
    return input_image.photo_in_scene(brdf, scene, light.image_exposure)  # RGB-only files through eval_rgb


def scene_list(envs: EnvChoice) -> dict[str, Scene]:
    """The scenes by role: ``distant``, ``env_seen``, ``env_unseen1``, ``env_unseen2``,
    ``shape_env`` and ``shape_distant``."""
    return {
        "distant": Scene(SPHERE),
        "env_unseen1": Scene(SPHERE, envs.unseen[0], False),
        "env_unseen2": Scene(SPHERE, envs.unseen[1], False),
        "env_seen": Scene(SPHERE, envs.seen, True),
        "shape_env": Scene(SUZANNE, envs.unseen[0], False),
        "shape_distant": Scene(SUZANNE),
    }


def load_environment(name: str) -> Environment:
    """An environment map by name, normalised as the training renders normalise it."""
    return lighting.load_environment(name)


def test_materials(count: int | None = None, names: Sequence[str] | None = None) -> list:
    """Held-out corpus materials (split ``test``), in corpus order: the first ``count``, or ``names``."""
    test = [m for m in generate_corpus(CORPUS_SIZE, CORPUS_SEED) if m.split == "test"]
    if names:
        by_name = {m.name: m for m in test}
        missing = [n for n in names if n not in by_name]
        if missing:
            raise SpecGenError(f"not test materials of the corpus: {', '.join(missing)} "
                               f"(test materials: {', '.join(sorted(by_name)[:8])}, ...)")
        return [by_name[n] for n in names]
    return test if count is None else test[:count]


def spectrum_source(material) -> str:
    """Where a test material's spectrum comes from: a measured reflectance, an Otsu 2018 draw
    (the same PCA model the Otsu 2018 baseline reconstructs with), or a metal's measured IOR."""
    if material.diffuse is None:
        return "metal (measured IOR)"
    if material.diffuse.source.startswith("Otsu2018/"):
        return "diffuse drawn from Otsu 2018's basis"
    return "measured diffuse reflectance"


# -- shapes -----------------------------------------------------------------------------------

def _normal_map_script() -> Path:
    return Path(__file__).resolve().parents[2] / "ops" / "normal_map.py"


def suzanne_normal_map(resolution: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Suzanne's normal map and mask at ``resolution``² (cached), or None when bpy is unavailable."""
    path = cache_root() / f"suzanne_normals_{resolution}.npz"
    if not path.is_file():
        script = _normal_map_script()
        if not script.is_file():
            return None
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.npz")
        try:
            res = subprocess.run([sys.executable, str(script), "--suzanne", "--resolution",
                                  str(resolution), "--out", str(tmp)], capture_output=True, text=True,
                                 timeout=600)
            if res.returncode != 0 or not tmp.is_file():
                return None
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
    with np.load(path) as data:
        return data["normals"].astype(np.float64), data["mask"].astype(bool)


def superellipsoid_normal_map(resolution: int, power: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """Analytic stand-in shape ``|x|^p + |y|^p + |z|^p = 1`` seen from +z (normal ∝ ∇)."""
    x, y = pixel_grid(resolution)
    x, y = x / 0.95, y / 0.95
    rest = 1.0 - np.abs(x) ** power - np.abs(y) ** power
    mask = rest > 0
    z = np.clip(rest, 0.0, None) ** (1.0 / power)
    g = np.stack([np.sign(x) * np.abs(x) ** (power - 1), np.sign(y) * np.abs(y) ** (power - 1),
                  z ** (power - 1)], axis=-1)
    norm = np.linalg.norm(g, axis=-1, keepdims=True)
    n = np.divide(g, norm, out=np.zeros_like(g), where=norm > 0)
    return n, mask


def shape_geometry(shape: str, resolution: int) -> tuple[Geometry, str]:
    """Geometry of ``shape`` and a label saying what was used (Suzanne or its analytic stand-in)."""
    if shape == SPHERE:
        return sphere_geometry(resolution), "analytic sphere"
    if shape == SUZANNE:
        captured = suzanne_normal_map(resolution)
        if captured is not None:
            return Geometry.from_normal_map(*captured), "Suzanne (Blender), normal map captured by ops/normal_map.py"
        n, mask = superellipsoid_normal_map(resolution)
        return Geometry.from_normal_map(n, mask), "superellipsoid (p = 4; bpy unavailable for Suzanne)"
    raise SpecGenError(f"unknown shape {shape!r}")


def scene_lighting(scene: Scene) -> dict:
    """``lights`` or ``environment`` keyword of a :class:`specgen_addon.render.Scene` for ``scene``."""
    if scene.env is None:
        return {"lights": DISTANT_LIGHTS}
    return {"environment": load_environment(scene.env)}
