"""The room's light from a chrome (mirror) ball: the light-probe method of Debevec (1998).

A mirror ball photographed from far away (an orthographic view: a long lens, the ball small in the
frame) reflects, at the point of normal n, the light arriving from r = 2(n·v)n − v, v the direction
to the camera. Every direction but a small cone behind the ball is seen once, so the photo unwraps
into an equirectangular environment in the camera's frame (x right, y up, z towards the camera:
the renderer's world frame, :func:`specgen_addon.render.environment.uv_to_direction`).

* **Reflectance**: a polished chrome ball reflects a fraction of the light (about 0.6–0.8; 0.75
  by default, or measured by the user): the unwrapped radiance is the photo divided by it.
* **Clipped sources**: pixels saturated in the probe photo (a lamp, the sun) hold only a lower
  bound of their radiance. Each clipped region becomes a distant light in its reflected direction;
  its power is unknown from the probe and is estimated from the diffuse ball
  (:func:`fit_clipped_powers`) when one is given, else left at the clipped level (flagged).

Numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from specgen_addon.common.errors import ImageInputError, SpecGenError
from specgen_addon.common.image_io import write_exr
from specgen_addon.common.limits import check_input_file
from specgen_addon.photo.ndimage_np import label, map_coordinates
from specgen_addon.photo.photo_lighting import Light, parse_lighting
from specgen_addon.photo.sphere_detect import luminance
from specgen_addon.photo.sphere_image import EXPOSURE, PhotoSource
from specgen_addon.photo.white_balance import LUMINANCE
from specgen_addon.render.environment import Environment, _texel_directions

#: Width of the unwrapped equirect map (height is half).
PROBE_WIDTH = 256
#: Default reflectance of a chrome ball.
CHROME_REFLECTANCE = 0.75
#: Directions within this angle (degrees) of straight behind the ball are not seen.
BLIND_CONE_DEG = 20.0


class ProbeError(SpecGenError):
    """A chrome-ball light probe cannot be used (no ball, a bad circle, nothing lit)."""


def check_reflectance(reflectance: float) -> None:
    """Refuse a chrome ball's reflectance outside (0, 1] (NaN included) in one sentence."""
    if not 0.0 < reflectance <= 1.0:
        raise ProbeError(f"the chrome ball's reflectance must lie in (0, 1], got {reflectance:g}")


@dataclass
class Probe:
    """An unwrapped light probe: the equirect environment (radiance, camera frame), the distant
    lights standing for its clipped sources, and notes for the run's report."""

    env_rgb: np.ndarray                              # (H, 2H, 3) float32, row 0 on top
    clipped_lights: list[tuple[np.ndarray, float]]   # (unit direction, solid angle sr) per clipped source
    notes: list[str] = field(default_factory=list)


def ball_normals(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Normals (size, size, 3) of a ball filling a size×size crop (x right, y up, z to the camera)
    and the mask of pixels on it."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    rr = x * x + y * y
    inside = rr < 1.0
    z = np.sqrt(np.clip(1.0 - rr, 0.0, None))
    return np.stack([x, y, z], -1), inside


def reflected(n: np.ndarray) -> np.ndarray:
    """Directions reflected about normals ``n`` (…, 3) of the view direction (0, 0, 1)."""
    return 2.0 * n[..., 2:3] * n - np.array([0.0, 0.0, 1.0])


def unwrap(crop: np.ndarray, reflectance: float = CHROME_REFLECTANCE, width: int = PROBE_WIDTH,
           saturated: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The equirect environment (width/2, width, 3) seen in a chrome-ball crop (S, S, 3, the ball
    filling it, linear), divided by ``reflectance``; and the map's texels that saw a saturated pixel.
    Directions in the blind cone behind the ball take the mean of the cone's rim."""
    check_reflectance(reflectance)
    s = crop.shape[0]
    d = _texel_directions(width // 2, width, 0.0)                 # (h, w, 3)
    h_vec = d + np.array([0.0, 0.0, 1.0])                         # the normal that reflects d to the camera
    norm = np.linalg.norm(h_vec, axis=-1, keepdims=True)
    n = h_vec / np.maximum(norm, 1e-9)
    col = (n[..., 0] + 1.0) * 0.5 * s - 0.5
    row = (1.0 - n[..., 1]) * 0.5 * s - 0.5
    env = np.stack([map_coordinates(crop[..., c], [row, col]) for c in range(3)], -1) / reflectance
    blind = d[..., 2] < -math.cos(math.radians(BLIND_CONE_DEG))
    rim = (d[..., 2] < -math.cos(math.radians(BLIND_CONE_DEG + 5))) & ~blind
    if rim.any():
        env[blind] = env[rim].mean(axis=0)
    sat = np.zeros(env.shape[:2], bool)
    if saturated is not None:
        sat = map_coordinates(saturated.astype(np.float64), [row, col]) > 0.25
        sat &= ~blind
    return np.clip(env, 0.0, None).astype(np.float32), sat


def clipped_sources(sat: np.ndarray, width: int) -> list[tuple[np.ndarray, float]]:
    """(unit direction, solid angle) of each connected clipped region of an equirect map."""
    if not sat.any():
        return []
    h = sat.shape[0]
    d = _texel_directions(h, width, 0.0)
    el = (0.5 - (np.arange(h) + 0.5) / h) * np.pi
    texel_sr = (np.pi / h) * (2 * np.pi / width) * np.cos(el)[:, None] * np.ones((1, width))
    labels, count = label(sat)
    out = []
    for k in range(1, count + 1):
        m = labels == k
        w = texel_sr[m]
        v = (d[m] * w[:, None]).sum(axis=0)
        out.append((v / np.linalg.norm(v), float(w.sum())))
    return out


#: Around a clipped source, the probe shows the lens's glare, not the room: this cone (degrees)
#: takes the background's level instead (the source itself becomes a distant light).
FLARE_DEG = 10.0


def remove_flare(env: np.ndarray, lights: list[tuple[np.ndarray, float]]) -> None:
    """Replace, in place, the texels within :data:`FLARE_DEG` of each clipped source by the map's
    median radiance."""
    d = _texel_directions(env.shape[0], env.shape[1], 0.0)
    near = np.zeros(env.shape[:2], bool)
    for direction, _ in lights:
        near |= d @ direction > math.cos(math.radians(FLARE_DEG))
    env[near] = np.median(env[~near], axis=0) if (~near).any() else 0.0


def read_probe(path: str | Path, circle: tuple[float, float, float] | None = None,
               mask: str | Path | None = None, encoding: str = "auto",
               reflectance: float = CHROME_REFLECTANCE, width: int = PROBE_WIDTH,
               gains=None) -> Probe:
    """Unwrap a chrome-ball photo (its circle given, from a mask, or found) into a :class:`Probe`;
    ``gains`` (3,) are the white-balance gains of the photo it lights (the same camera)."""
    check_reflectance(reflectance)
    try:
        check_input_file(path, "chrome ball photo")
    except SpecGenError as exc:
        raise ProbeError(str(exc)) from None
    wb = None if gains is None else tuple(float(g) for g in gains)
    try:
        crop = PhotoSource(Path(path), encoding=encoding, circle=circle, mask=mask,
                           white_gains=wb).crop(size=256)
    except ImageInputError as exc:
        if circle is None and mask is None:   # it was looked for, and not found
            advice = "" if "give" in str(exc) else " (give its mask or circle)"   # said once
            raise ProbeError(f"chrome ball not found: {exc}{advice}") from None
        raise ProbeError(f"chrome ball: {exc}") from None
    env, sat = unwrap(crop.image.astype(np.float64), reflectance, width, crop.saturated)
    if not np.any(env > 0):
        raise ProbeError(f"{path}: the chrome ball reflects nothing (a black probe)")
    lights = clipped_sources(sat, width)
    notes = [f"chrome ball {crop.describe()}"]
    if lights:
        remove_flare(env, lights)
        notes.append(f"{len(lights)} clipped light source(s) in the probe: each becomes a distant light "
                     f"(its glare within {FLARE_DEG:g}° replaced by the background), its power estimated "
                     "(the probe holds only a lower bound)")
    return Probe(env, lights, notes)


def fit_clipped_powers(probe: Probe, photo: np.ndarray, exposure: float = 1.0) -> list[float]:
    """Radiances (of a white surface facing each, in the photo's units / ``exposure``) of the
    probe's clipped sources that, with the unclipped environment (in the same units: the probe and
    the ball photographed alike), best explain a diffuse ball's photo (S, S, 3, linear): a
    Lambertian model, its albedo at most 1, fitted by non-negative least squares on the luminance."""
    if not probe.clipped_lights:
        return []
    s = photo.shape[0]
    n, inside = ball_normals(s)
    lum = luminance(photo)
    nn = n[inside]
    env = Environment(probe.env_rgb)
    e_env = env.irradiance_rgb(nn) @ LUMINANCE / np.pi   # radiance of a white ball
    cols = [e_env] + [np.maximum(nn @ d, 0.0) for d, _ in probe.clipped_lights]   # power 1 = radiance 1
    a = np.stack(cols, -1) * exposure
    y = lum[inside]
    coef = _nnls(a, y)
    if not coef[0] <= 1.0:   # no ball reflects more than it receives: albedo ≤ 1, the lights do the rest
        coef = np.concatenate([[1.0], _nnls(a[:, 1:], y - a[:, 0])])
    albedo = coef[0] if coef[0] > 1e-6 else 1.0   # the environment explains nothing: the lights alone
    return [float(c / albedo) for c in coef[1:]]


def _nnls(a: np.ndarray, y: np.ndarray, iterations: int = 200) -> np.ndarray:
    """Non-negative least squares by projected coordinate descent (a few unknowns)."""
    x = np.maximum(np.linalg.lstsq(a, y, rcond=None)[0], 0.0)
    g = a.T @ a
    b = a.T @ y
    for _ in range(iterations):
        for j in range(x.size):
            if g[j, j] > 0:
                x[j] = max(0.0, x[j] + (b[j] - g[j] @ x) / g[j, j])
    return x


def probe_lighting(probe: Probe, env_path: str | Path, photo: np.ndarray | None = None,
                   overwrite: bool = False):
    """The :class:`~specgen_addon.photo.photo_lighting.InputLighting` of a probe: its environment written
    to ``env_path`` (an EXR, used calibrated: its values are radiance as photographed) plus a
    distant light per clipped source, powered by :func:`fit_clipped_powers` on the diffuse ball's
    ``photo`` (or at the clipped level, 1/solid angle × the probe's peak, without one)."""
    env = probe.env_rgb
    write_exr(env_path, {"R": env[..., 0], "G": env[..., 1], "B": env[..., 2]}, overwrite=overwrite)
    if probe.clipped_lights and photo is not None:
        powers = fit_clipped_powers(probe, photo)
        probe.notes.append("clipped source power(s) fitted to the diffuse ball: "   # as the lights' labels
                           + ", ".join(f"×{p / EXPOSURE:g}" for p in powers)
                           + " (1: the canonical key light)")
    else:
        peak = float(env.max())
        powers = [peak * sr for _, sr in probe.clipped_lights]
        if powers:
            probe.notes.append("clipped source power(s) at their clipped level (a lower bound; no diffuse "
                               "ball to estimate them from)")
    # photo units: a photo value v is radiance v / EXPOSURE to the renderer (input_image.EXPOSURE),
    # and a light of power 1 gives a white surface facing it a radiance of 1
    lights = tuple(Light(tuple(d), p / EXPOSURE) for (d, _), p in zip(probe.clipped_lights, powers) if p > 0)
    return parse_lighting(str(env_path), exposure=1.0 / EXPOSURE, lights=lights, calibrated=True,
                          key_light=False)


def lighting_from_probe(probe_path: str | Path, source, env_path: str | Path,
                        circle: tuple[float, float, float] | None = None, mask: str | Path | None = None,
                        reflectance: float | None = None, overwrite: bool = False):
    """The lighting of a chrome-ball photo for a :class:`~specgen_addon.photo.sphere_image.PhotoSource`
    taken alike (same encoding): the probe unwrapped (:func:`read_probe`), its environment written to
    ``env_path`` and its clipped sources' powers fitted to the source's ball
    (:func:`probe_lighting`); ``reflectance`` None is :data:`CHROME_REFLECTANCE`. Returns
    ``(lighting, notes)`` (the CLI's ``--light-probe`` and the panel's Chrome Ball)."""
    crop = source.crop()
    # the same camera: the photo's white-balance gains apply to the chrome ball too
    probe = read_probe(probe_path, circle=circle, mask=mask, encoding=source.encoding,
                       reflectance=CHROME_REFLECTANCE if reflectance is None else reflectance,
                       gains=crop.white_gains)
    photo = crop.image.astype(np.float64)
    lighting = probe_lighting(probe, env_path, photo, overwrite=overwrite)
    return lighting, list(probe.notes)
