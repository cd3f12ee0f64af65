"""The network's input for a photo under a known light: the photo refitted, re-rendered in the studio.

The shipped networks learnt from spheres rendered under the canonical studio
(:func:`specgen_addon.photo.sphere_image.render_input`: Blender's ``studio`` map and a D65 key light
from the upper left). A real photo is lit by its room: one lamp from another side, a black
terminator, and at the light's nominal power an albedo above 1, about twice as bright as a white
ball in the studio (lab/notebook/real-photos-network.md). A per-channel gain (:meth:`InputLighting.network_gain`)
corrects the colour of the light but not where it comes from.

So when the photo's lighting is given and is not the studio, the photo is first explained by a
small analytic BRDF under that lighting (:func:`specgen_addon.generate.analytic_fit.fit_photo`:
Lambert + one GGX lobe with Schlick Fresnel, no clear coat; a few parameters per channel) and
that BRDF is rendered under the canonical studio: the network is given the photo it would have
been trained on for this material. The refinement still fits the real photo under its
real light. The pipeline shows the network the re-render when the network's table is the result
(no refinement; :func:`network_crop`). The canonical lighting never goes through here, so its path
is unchanged bit for bit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from specgen_addon.generate.analytic_fit import PhotoFit, fit_photo
from specgen_addon.photo.resample import resample_square
from specgen_addon.photo.sphere_image import SphereCrop, render_input

#: Size (pixels) of the photo the analytic BRDF is fitted to: the network's own input size; the
#: fit needs the shading's shape, not every pixel.
FIT_SIZE = 64
#: Clear-coat roughnesses tried by the refit: none. On a matte ball the fit explains the gentle
#: fall-off with a broad coat (weight 1.3–1.7, α_c ≈ 0.33) over a rough base lobe; re-rendered in
#: the studio it reads as a gloss, and the network alone predicts the other photos of that ball
#: 0.3–2.2 dB worse than from the same fit without it (lab/notebook/real-photos-network.md).
COAT_ALPHAS: tuple[float, ...] = ()


@dataclass(frozen=True)
class CanonicalInput:
    """The network's input re-rendered under the canonical studio, and how it was made."""

    crop: SphereCrop   # what the network is given (``copied``: a canonical render)
    fit: PhotoFit      # the analytic BRDF fitted to the photo under its own lighting
    seconds: float     # fit + re-render, wall clock

    def describe(self) -> str:
        """One line for a run's report."""
        return (f"network input: the photo refitted under its light and re-rendered in the canonical "
                f"studio ({self.fit.summary()}; {self.seconds:.1f} s)")


def canonical_input(photo: np.ndarray, lighting, clip_level: float | np.ndarray | None = None,
                    exclude: np.ndarray | None = None, cancel=None) -> CanonicalInput:
    """Fit an analytic BRDF to ``photo`` (linear sRGB (S, S, 3) on the canonical sphere crop) under
    ``lighting`` (:class:`~specgen_addon.photo.photo_lighting.InputLighting`, not canonical) and
    render it under the canonical studio at the photo's size.

    ``clip_level`` and ``exclude`` leave clipped and saturated pixels out of the fit.
    """
    if lighting.is_canonical:
        raise ValueError("the photo is already under the canonical studio: nothing to re-render")
    t0 = time.perf_counter()
    photo = np.asarray(photo, dtype=np.float64)
    size = photo.shape[0]
    # left out: clipped or saturated pixels, and any fit pixel that a downsample mixes them into
    bad = np.zeros(photo.shape[:2], bool) if exclude is None else np.asarray(exclude, bool).copy()
    if clip_level is not None:
        bad |= np.any(photo >= clip_level, axis=-1)
    small = min(size, FIT_SIZE)
    fit_photo_small = resample_square(photo, small).transpose(1, 2, 0)
    bad_small = resample_square(np.repeat(bad[..., None], 3, -1).astype(np.float32), small)[0] > 0
    fit = fit_photo(fit_photo_small, lighting.scene(small), lighting.image_exposure, coat_alphas=COAT_ALPHAS,
                    max_edge=1.0, exclude=bad_small, cancel=cancel)
    image = render_input(fit.brdf, size)   # EXPOSURE × radiance, as every training input
    return CanonicalInput(SphereCrop(image, copied=True), fit, time.perf_counter() - t0)


def network_crop(crop: SphereCrop, photo: np.ndarray, lighting, clip_level: float | np.ndarray | None = None,
                 cancel=None, refit: bool = True) -> tuple[SphereCrop, CanonicalInput | None]:
    """What the network is given for ``photo`` under ``lighting``: under the canonical studio, or
    without ``refit``, the photo itself × :meth:`InputLighting.network_gain` (the crop's own kind);
    else its canonical re-render (:func:`canonical_input`).

    The pipeline refits only when the network's table is the result (no refinement): on the
    shared real photos the refinement does better from the photo's own table (with the light
    from a chrome ball 28.06 against 26.66 dB, estimated 26.60 against 26.08; from the file's
    light 26.38 against 26.70), while the network alone gains 15–17 dB from the re-render
    (lab/notebook/real-photos-network.md)."""
    if lighting.is_canonical or not refit:
        return SphereCrop(photo * lighting.network_gain(), crop.copied), None
    made = canonical_input(photo, lighting, clip_level, crop.saturated, cancel)
    return made.crop, made
