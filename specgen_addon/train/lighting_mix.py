"""Training-input lighting drawn at random per step, by linearity of rendering in the lighting.

A render is linear in its lights, so each material is rendered once under a few *components*
and every training step mixes them with fresh random weights:

* ``canonical``: the canonical input (:func:`specgen_addon.photo.sphere_image.render_input`), and its
  exact 8-bit PNG version (clipped, quantised at full resolution);
* ``env``: one of the bundled maps (:data:`specgen_addon.render.environment_maps.TRAIN_ENVS`) at one of eight
  rotations, chosen per material (:func:`env_variant`), with the key light; a step scales it by a
  random exposure 2^U(−1, 1);
* ``sun0`` … ``sun5``: a D65 distant light (irradiance π) from each of :data:`SUN_DIRECTIONS`;
* ``sky``: :data:`SKY_DIRECTIONS`, twelve weak distant lights over the upper hemisphere (a
  stand-in for a sky dome; its blue tint is applied in RGB at mixing time).

A step draws one of three modes (:data:`MODE_P` by default; training passes its config's
``canonical_fraction`` and splits the rest evenly): canonical (linear or PNG), environment
(random exposure), or synthetic (one or two suns of random strength and warmth plus a sky of
random strength, random exposure). Synthetic and environment images are then clipped and
8-bit quantised with probability :data:`P_QUANTISE` (at the network's resolution: an
approximation of quantising the full-size image, which only the canonical PNG is).
"""

from __future__ import annotations

import functools
import zlib

import numpy as np

from specgen_addon.photo import sphere_image as input_image
from specgen_addon.spectral import spectra
from specgen_addon.photo.resample import aa_bilinear_weights
from specgen_addon.render import DistantLight, Scene, environment_maps as lighting, sphere_geometry
from specgen_addon.train.data import material_key, render_all

#: Unit directions (world; camera looks down −z, +y up) of the six synthetic suns.
SUN_DIRECTIONS = ((-0.6, 0.6, 0.53), (0.7, 0.5, 0.5), (0.0, 0.9, 0.44), (-0.85, -0.1, 0.52),
                  (0.3, -0.2, 0.93), (0.55, 0.75, -0.37))
#: Fibonacci points on the upper (+y) hemisphere: the synthetic sky.
SKY_DIRECTIONS = tuple(
    (float(np.sqrt(1 - y * y) * np.cos(2.399963 * i)), float(y), float(np.sqrt(1 - y * y) * np.sin(2.399963 * i)))
    for i, y in enumerate((np.arange(12) + 0.5) / 12))
COMPONENTS = ("canonical", "canonical_png", "env") + tuple(f"sun{i}" for i in range(len(SUN_DIRECTIONS))) + ("sky",)
#: Probabilities of the canonical, environment and synthetic modes.
MODE_P = (0.4, 0.3, 0.3)
P_QUANTISE = 0.5
#: Environment sampling of the ``env`` component relative to the evaluation's (inputs use 0.5).
ENV_SAMPLING_SCALE = 0.125
#: Number of environment variants :func:`env_variant` chooses among (see input_image.training_variant).
N_ENV_VARIANTS = 24


def env_variant(name: str) -> int:
    """Training-lighting variant (1 … 24) of the material called ``name`` (stable CRC-32)."""
    return 1 + zlib.crc32(name.encode("utf-8")) % N_ENV_VARIANTS


def _light_scene(directions, irradiance: float):
    lights = [DistantLight(d, irradiance, spectra.DEFAULT_ILLUMINANT) for d in directions]
    return Scene(sphere_geometry(input_image.CANONICAL_SIZE), lights)


_SCENES: dict[str, object] = {}


def render_component(brdf, name: str, component: str) -> np.ndarray:
    """Linear-sRGB render (128, 128, 3) of ``brdf`` (called ``name``) under one component."""
    if component == "canonical":
        return input_image.render_input(brdf)
    if component == "canonical_png":
        return quantise(input_image.render_input(brdf))
    if component == "env":
        env, rotation, exposure = input_image.training_variant(env_variant(name))
        return _render(brdf, _env_scene(env, rotation), exposure)
    if component not in _SCENES:
        if component == "sky":
            _SCENES[component] = _light_scene(SKY_DIRECTIONS, float(np.pi) / len(SKY_DIRECTIONS))
        else:
            _SCENES[component] = _light_scene([SUN_DIRECTIONS[int(component[3:])]], float(np.pi))
    return _render(brdf, _SCENES[component], input_image.EXPOSURE)


def _render(brdf, scene, exposure: float) -> np.ndarray:
    if input_image._is_rgb_only(brdf):
        rgb = scene.render_rgb(brdf).rgb
    else:
        rgb = scene.render_spectral(brdf, spectra.DEFAULT_WAVELENGTHS_NM).rgb
    return (np.clip(rgb, 0.0, None) * exposure).astype(np.float32)


@functools.lru_cache(maxsize=4)
def _env_scene(env_name: str, rotation_rad: float):
    """A training map with the key light, at a quarter of the input sampling (:data:`ENV_SAMPLING_SCALE`):
    an augmentation image, whose extra noise is far below the 8-bit quantisation it may get."""
    env = lighting.load_environment(env_name, rotation_rad=rotation_rad)
    return Scene(sphere_geometry(input_image.CANONICAL_SIZE), [input_image._key_light()], env,
                 sampling=input_image.input_sampling().scaled(ENV_SAMPLING_SCALE / 0.5))


def quantise(image: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] and quantise to 8-bit sRGB (then decode back to linear)."""
    q = np.round(spectra.srgb_encode(np.clip(image, 0.0, 1.0)) * 255.0) / 255.0
    return spectra.srgb_decode(q).astype(np.float32)


def mix_lighting(stack: np.ndarray, rng: np.random.Generator, canonical_p: float = MODE_P[0]) -> np.ndarray:
    """One input image (3, S, S) from a material's component stack (len(COMPONENTS), 3, S, S).

    ``canonical_p`` is the probability of the canonical mode; the environment and synthetic
    modes share the rest evenly (the default reproduces :data:`MODE_P`).
    """
    stack = stack.astype(np.float32, copy=False)
    u = rng.random()
    if u < canonical_p:
        return stack[1] if rng.random() < 0.5 else stack[0]
    if u < canonical_p + 0.5 * (1.0 - canonical_p):
        img = stack[2] * np.float32(2.0 ** rng.uniform(-1.0, 1.0))
    else:
        n_sun = 1 + int(rng.random() < 0.4)
        suns = rng.choice(len(SUN_DIRECTIONS), size=n_sun, replace=False)
        img = np.zeros_like(stack[0])
        for k in suns:
            warm = rng.uniform(0.0, 0.15)  # low sun: warmer (RGB tint, an approximation)
            tint = np.array([1.0 + warm, 1.0, 1.0 - warm], np.float32)[:, None, None]
            img += stack[3 + k] * tint * np.float32(rng.uniform(0.4, 1.2))
        sky_tint = np.array([0.8, 0.95, 1.25], np.float32)[:, None, None]
        img += stack[3 + len(SUN_DIRECTIONS)] * sky_tint * np.float32(rng.uniform(0.0, 0.8))
        img *= np.float32(2.0 ** rng.uniform(-0.7, 0.7))
    if rng.random() < P_QUANTISE:
        img = quantise(img.transpose(1, 2, 0)).transpose(2, 0, 1)
    return np.ascontiguousarray(img, dtype=np.float32)


class ComponentCache:
    """Component stacks ``(len(COMPONENTS), 128, 128, 3)`` float16 per material, one ``.npy`` each.

    Keyed by the material's content (:func:`~.data.material_key`), so a resumed or repeated run
    renders only what is missing, and runs with other seeds or configs share the renders.
    """

    def __init__(self, cache_dir):
        from pathlib import Path

        self.cache_dir = Path(cache_dir)

    def path(self, mat):
        return self.cache_dir / f"mix_{mat.name.replace('/', '_')}_{material_key(mat)}.npy"

    def missing(self, mats):
        return [m for m in mats if not self.path(m).is_file()]

    def make(self, mat) -> None:
        import os

        canonical = render_component(mat.brdf, mat.name, "canonical")
        stack = np.stack([canonical, quantise(canonical)] +
                         [render_component(mat.brdf, mat.name, c) for c in COMPONENTS[2:]]).astype(np.float16)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        path = self.path(mat)
        tmp = path.with_name(path.stem + f".{os.getpid()}.tmp.npy")
        np.save(tmp, stack)
        tmp.replace(path)

    def fill(self, mats, workers: int = 2, progress=None) -> None:
        """Render what is missing, grouped by environment variant (prepared scenes are reused)."""
        todo = sorted(self.missing(mats), key=lambda m: env_variant(m.name))
        if todo:
            render_all(self.make, todo, workers, progress)

    def load(self, mat, image_size: int) -> np.ndarray:
        """The stack at network resolution ``(len(COMPONENTS), 3, S, S)`` float16."""
        return resample_stack(np.load(self.path(mat)), image_size)


def resample_stack(stack: np.ndarray, size: int) -> np.ndarray:
    """``(K, H, W, 3)`` → ``(K, 3, size, size)`` float16 with the antialiased bilinear weights of
    :func:`specgen_addon.photo.resample.resample_square`, applied separably (two small matrix products
    instead of its one four-index ``einsum``, which is ~100× slower at 128² → 64²)."""
    chw = np.ascontiguousarray(np.asarray(stack, dtype=np.float32).transpose(0, 3, 1, 2))
    if chw.shape[2:] == (size, size):
        return chw.astype(np.float16)
    wy = aa_bilinear_weights(chw.shape[2], size).astype(np.float32)
    wx = aa_bilinear_weights(chw.shape[3], size).astype(np.float32)
    return (wy @ chw @ wx.T).astype(np.float16)
