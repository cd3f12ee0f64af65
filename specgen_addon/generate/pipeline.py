"""Photo → spectral BRDF: :func:`generate` is Generate's one front door (CLI ``infer``, batch.py, the
panel).

1. the photo is read and its sphere cropped to the canonical frame
   (:func:`specgen_addon.photo.sphere_image.load_sphere_image`);
2. it is brought to the canonical white level of its input lighting
   (:meth:`~specgen_addon.photo.photo_lighting.InputLighting.network_gain`) and the network generates the
   table (:func:`specgen_addon.model.runtime.inference.generate_brdf`): unless weights are given, the shipped network
   for a sphere copied from a canonical frame, or the one for a sphere resampled from a photo
   (:func:`specgen_addon.model.shipped_weights`);
3. optionally (``latent_fit``, torch only), the network's latent is fitted to the photo under that
   lighting and the table decoded again from it (:func:`specgen_addon.generate.latent_fit.fit_latent`);
4. unless switched off, the table is refined against the photo under that lighting
   (:func:`specgen_addon.generate.refine.refine_brdf`). Without refinement the network's table is returned
   untouched.

With ``model="thin-film"`` steps 2–4 are replaced by the thin-film family's fit to the photo
(:func:`specgen_addon.generate.thin_film.fit_thin_film`): for interference films (soap, oil, anodised
metal) whose angle-dependent colour the network's prior does not place. Where the crop resampled the
sphere, the fit models the photo's blur as the refinement does.

With ``out_dir`` the table is then baked into what Blender reads
(:func:`specgen_addon.bake.lookup.bake_lookup`), as the panel and batch.py ask.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from specgen_addon.bake.lookup import DEFAULT_TOLERANCE, AtlasInfo, bake_lookup, check_lookup_outputs
from specgen_addon.brdf.table import N_PHI_D, BRDFTable
from specgen_addon.common.atomic_io import make_dirs
from specgen_addon.common.errors import SpecGenError, WeightsError
from specgen_addon.common.interrupts import OutputGuard
from specgen_addon.generate.canonical_input import network_crop
from specgen_addon.generate.latent_fit import fit_latent
from specgen_addon.generate.refine import CLIP_LEVEL, RefineOptions, refine_brdf, render_under
from specgen_addon.generate.refine.blur import BLUR_CANDIDATES_PX
from specgen_addon.generate.thin_film import fit_thin_film
from specgen_addon.photo.read import stores_floats
from specgen_addon.model.checksums import DamagedWeightsError
from specgen_addon.model.runtime.inference import generate_brdf, sphere_crop
from specgen_addon.photo.photo_lighting import InputLighting
from specgen_addon.photo.sphere_image import PhotoSource, SphereCrop
from specgen_addon.generate.models import MODELS
from specgen_addon.render import sphere_geometry
from specgen_addon.render.photo_reproduction import reproduction
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]

#: Share of the progress bar taken by the network when refinement (and no latent fit) follows.
NETWORK_SHARE = 0.45
#: Generate's network evaluates bands at most this far apart (nm) and interpolates the others
#: linearly in λ (:func:`specgen_addon.model.runtime.inference.network_bands`): every other band
#: of the default 20 nm grid, about 40 % of the network's time saved, the table within 1 % rms of
#: the network's at every band and as accurate on real and synthetic materials (within 0.15 dB on
#: the mean; docs/dev/benchmarks.md); ``every_band`` evaluates them all.
NETWORK_BAND_GAP_NM = 40.0


@dataclass
class Generated:
    """The table a front end uses, and the refinement's report (``None`` when switched off)."""

    table: BRDFTable
    refinement: object | None = None   # specgen_addon.generate.refine.RefineResult
    latent_fit: object | None = None   # specgen_addon.generate.latent_fit.LatentFitResult (latent_fit=True)
    film_fit: object | None = None     # specgen_addon.generate.thin_film.ThinFilmFit (model="thin-film")
    crop: object | None = None         # specgen_addon.photo.sphere_image.SphereCrop: the circle used, saturation
    network_reproduction: object | None = None   # refine.report.Reproduction of the network alone (no refinement)
    lookup: AtlasInfo | None = None    # what Blender reads, baked into ``out_dir`` (generate(out_dir=…))
    canonical_input: object | None = None   # generate.canonical_input.CanonicalInput (a non-canonical light)

    @property
    def warnings(self) -> list[str]:
        fit = [] if self.film_fit is None else list(self.film_fit.warnings)
        return fit + ([] if self.refinement is None else list(self.refinement.warnings))


def load_photo(image) -> tuple[np.ndarray, bool]:
    """The canonical sphere crop (S, S, 3) of a path or array, and whether it is linear HDR (EXR
    or array: no pixel counts as clipped) rather than an 8/16-bit sRGB file."""
    crop, linear = load_photo_crop(image)
    return crop.image.astype(np.float64), linear


def load_photo_crop(image) -> tuple[SphereCrop, bool]:
    """:func:`load_photo` as a :class:`~specgen_addon.photo.sphere_image.SphereCrop` (which also says
    whether the sphere was copied or resampled, and so which shipped network it gets)."""
    if isinstance(image, PhotoSource):
        return sphere_crop(image), image.linear
    linear = not isinstance(image, (str, Path)) or stores_floats(image)
    return sphere_crop(image), linear


def generate(image, lighting=None, refine: bool = True, weights=None, wavelengths_nm=None,
             backend: str | None = "torch", progress: ProgressFn | None = None,
             cancel: CancelFn | None = None, model: str = "network", latent_fit: bool = False, *,
             out_dir: str | os.PathLike | None = None, name: str = "brdf", n_phi_d: int = N_PHI_D,
             tolerance: float = DEFAULT_TOLERANCE, save_table: bool = False, preview: bool = False,
             overwrite: bool = True, every_band: bool = False) -> Generated:
    """Generate (and by default refine) the spectral BRDF of the sphere in ``image``.

    ``lighting`` is an :class:`~specgen_addon.photo.photo_lighting.InputLighting` (default: canonical).
    ``model`` is one of :data:`MODELS` (``"thin-film"`` ignores ``refine``, ``weights``, ``backend``).
    ``backend`` ``None`` picks onnx when onnxruntime is importable (a stock Blender ships no torch)
    and says so when it has to fall back to torch; torch for the latent fit (it needs gradients).
    ``latent_fit`` fits the network's latent to the photo before any refinement (torch backend only).
    The network evaluates every band with ``every_band``, else those :data:`NETWORK_BAND_GAP_NM`
    apart, the others interpolated in λ.
    ``progress(fraction)`` and ``cancel()`` are passed down; cancelling raises
    :class:`~specgen_addon.common.errors.Cancelled` and returns nothing.

    With ``out_dir``, the table is also baked into what Blender reads, ``<name>_lookup.*`` (and
    with ``save_table`` ``<name>.npz``, with ``preview`` ``<name>_preview.png``): see
    :func:`specgen_addon.bake.lookup.bake_lookup`; ``result.lookup`` describes it and carries the
    refinement's and the thin-film fit's reports. Progress is then 0–0.8 generation, 0.8–1 bake.
    Without ``overwrite`` existing outputs of ``name`` are refused up front; whatever fails or is
    cancelled leaves nothing new in ``out_dir``.
    """
    kwargs = {"lighting": lighting, "refine": refine, "weights": weights, "wavelengths_nm": wavelengths_nm,
              "cancel": cancel, "model": model, "latent_fit": latent_fit, "every_band": every_band}
    if out_dir is None:
        return _generate_any_backend(image, backend, progress=progress, **kwargs)

    out = check_lookup_outputs(out_dir, name, overwrite)
    sub = (lambda lo, hi: (lambda f: progress(lo + (hi - lo) * f))) if progress else (lambda lo, hi: None)
    with OutputGuard([out]):  # failed, cancelled or interrupted: nothing it made stays in out_dir
        make_dirs(out)
        generated = _generate_any_backend(image, backend, progress=sub(0.0, 0.8), **kwargs)
        info = bake_lookup(generated.table, out, name, n_phi_d=n_phi_d, tolerance=tolerance,
                           save_table=save_table, preview=preview, progress=sub(0.8, 1.0), cancel=cancel)
    info.refinement = generated.refinement
    info.film_fit = generated.film_fit
    info.crop = generated.crop
    generated.lookup = info
    return generated


def choose_backend() -> str:
    """``"onnx"`` when onnxruntime is importable (a stock Blender ships no torch), else ``"torch"``."""
    import importlib.util

    return "onnx" if importlib.util.find_spec("onnxruntime") is not None else "torch"


def _generate_any_backend(image, backend: str | None, **kwargs) -> Generated:
    """:func:`_generate` with ``backend``, or with ``None`` the one :func:`choose_backend` picks:
    onnx, or torch with a warning where the onnx graphs are missing or unusable."""
    chosen = backend or ("torch" if kwargs.get("latent_fit") else choose_backend())   # its gradients: torch
    try:
        return _generate(image, backend=chosen, **kwargs)
    except WeightsError as exc:
        import importlib.util
        import warnings

        if backend is not None or chosen != "onnx" or importlib.util.find_spec("torch") is None \
                or isinstance(exc, DamagedWeightsError):
            raise
        # the graphs are missing or unusable: say so, the backend never changes silently
        warnings.warn(f"the onnx backend cannot run ({exc}); using the torch backend", stacklevel=3)
        return _generate(image, backend="torch", **kwargs)


def _generate(image, lighting=None, refine: bool = True, weights=None, wavelengths_nm=None,
              backend: str = "torch", progress: ProgressFn | None = None,
              cancel: CancelFn | None = None, model: str = "network", latent_fit: bool = False,
              every_band: bool = False) -> Generated:
    """:func:`generate`'s table, without the bake, with one ``backend``."""
    if model not in MODELS:
        raise SpecGenError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    if latent_fit and model != "network":
        raise SpecGenError(f"the latent fit is the network's; it does not apply to model {model!r}")
    if latent_fit and backend != "torch":
        raise SpecGenError("the latent fit needs the torch backend (gradients through the network); "
                           "use --backend torch or leave the latent fit off")
    lighting = lighting or InputLighting()
    crop, linear = load_photo_crop(image)
    photo = crop.image.astype(np.float64)
    # an 8/16-bit camera clips before any white balance: full scale per channel is the balance's gain
    full_scale = np.ones(3) if crop.white_gains is None else np.asarray(crop.white_gains, np.float64)
    clip_level = None if linear else CLIP_LEVEL * full_scale   # per channel
    src = str(image.path) if hasattr(image, "path") else str(image) if isinstance(image, (str, Path)) else "image"

    def sub(lo: float, hi: float) -> ProgressFn | None:
        return None if progress is None else (lambda f: progress(lo + (hi - lo) * f))

    if model == "thin-film":
        wl = DEFAULT_WAVELENGTHS_NM if wavelengths_nm is None else np.asarray(wavelengths_nm, np.float64)
        # a resampled crop spreads the highlight: the fit models that blur (docs/thin_film_fit.md)
        fit = fit_thin_film(photo, lighting, clip_level=clip_level,
                            progress=sub(0.0, 0.8), cancel=cancel,
                            blur_px=(0.0,) if crop.copied else BLUR_CANDIDATES_PX)
        table = fit.table(wl, progress=sub(0.8, 1.0), cancel=cancel)
        table.metadata = {**table.metadata, "input_image": src, "input_lighting": lighting.label}
        return Generated(table, film_fit=fit, crop=crop)

    # progress: the network, then the latent fit (about 4× the network's time), then refinement
    ends = np.cumsum([NETWORK_SHARE, 4.0 * NETWORK_SHARE if latent_fit else 0.0,
                      1.0 - NETWORK_SHARE if refine else 0.0])
    ends = ends / ends[-1]
    # the photo's crop, not cut again: how the photo was cut chooses the shipped network
    # under a given room light the network alone sees the photo refitted and re-rendered in the studio
    network_input, canonical = network_crop(crop, photo, lighting, clip_level, cancel, refit=not refine)
    table = generate_brdf(network_input, weights=weights, wavelengths_nm=wavelengths_nm,
                          backend=backend, progress=sub(0.0, ends[0]), cancel=cancel,
                          band_gap_nm=None if every_band else NETWORK_BAND_GAP_NM)
    fitted = None
    if latent_fit:
        fitted = fit_latent(network_input, photo, lighting, weights, wavelengths_nm, clip_level=clip_level,
                            network_table=table, progress=sub(ends[0], ends[1]), cancel=cancel)
        table = fitted.table
    table.metadata = {**table.metadata, "input_image": src, "input_lighting": lighting.label}
    if not refine:
        return Generated(table, latent_fit=fitted, crop=crop, canonical_input=canonical,
                         network_reproduction=network_reproduction(table, photo, lighting, clip_level, crop.saturated))

    options = RefineOptions(clip_level=None if linear else CLIP_LEVEL, full_scale=tuple(full_scale.tolist()),
                            exclude=crop.saturated)
    result = refine_brdf(table, photo, lighting, options, progress=sub(ends[1], 1.0), cancel=cancel)
    return Generated(result.table, result, latent_fit=fitted, crop=crop, canonical_input=canonical)


def network_reproduction(table: BRDFTable, photo: np.ndarray, lighting, clip_level: float | np.ndarray | None,
                         exclude: np.ndarray | None = None):
    """How well a table alone reproduces the photo under its lighting (RGB PSNR, ΔE2000 over the
    sphere's unsaturated pixels): the figure a run without refinement reports. ``clip_level``
    (per channel, or None for a linear photo): photo values at or above it are clipped, and the
    render is clipped at the full scale it is :data:`CLIP_LEVEL` of."""
    scene = lighting.scene(photo.shape[0])
    img = render_under(table, scene, lighting.image_exposure)
    if clip_level is not None:
        img = np.minimum(img, np.asarray(clip_level) / CLIP_LEVEL)
    inside = np.any(photo > 0, axis=-1) | np.any(img > 0, axis=-1)

    inside &= sphere_geometry(photo.shape[0]).mask
    if exclude is not None:
        inside &= ~exclude
    if clip_level is not None:
        inside &= ~np.any(photo >= clip_level, axis=-1)
    return reproduction(photo[inside], img[inside])
