"""Image metrics: PSNR and SSIM per wavelength band and averaged, via scikit-image.

One normalisation is used everywhere (training validation, evaluation tables, benches):

1. both images (H, W, C) — C wavelength bands, or 3 RGB channels — are divided by the same scale
   ``s``: the 99.9th percentile of the ground truth over the covered pixels and all bands (a robust
   "peak": the plain maximum of a render with a sharp highlight hinges on a handful of pixels and
   moves with sampling noise);
2. per band, PSNR uses ``data_range = 1`` and the mean squared error over the covered pixels
   (``skimage.metrics.peak_signal_noise_ratio`` on the masked values);
3. per band, SSIM (Wang et al. 2004, ``skimage.metrics.structural_similarity``, 7×7 uniform window,
   ``data_range = 1``) is computed on the whole image and its map averaged over the covered pixels;
4. the averages are arithmetic means over bands (of dB for PSNR). Identical bands give PSNR = inf.

No clipping: values above the scale (highlights) still count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from specgen_addon.common.errors import SpecGenError
from specgen_addon.spectral.colour_tables import mallett2019_basis

#: Percentile of the ground truth (covered pixels, all bands) that maps to 1.
PEAK_PERCENTILE = 99.9
#: One-line statement of the normalisation, for reports.
NORMALISATION_TEXT = (
    f"PSNR and SSIM (scikit-image) per wavelength band, then averaged over bands; both images are "
    f"divided by the ground truth's {PEAK_PERCENTILE:g}th percentile over the covered pixels and all "
    f"bands, data_range = 1, no clipping; PSNR's MSE and SSIM's map are averaged over the covered "
    f"pixels only (SSIM: 7×7 uniform window).")


@dataclass
class SpectralMetrics:
    """Per-band ``psnr`` (dB) and ``ssim`` arrays (C,), their means, and the normalising ``scale``."""

    psnr: np.ndarray
    ssim: np.ndarray
    psnr_mean: float
    ssim_mean: float
    scale: float


def _as_stack(x: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 2:
        x = x[..., None]
    if x.ndim != 3:
        raise SpecGenError(f"{name} must be H×W or H×W×C, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise SpecGenError(f"{name} holds NaN or Inf values")
    return x


def normalisation_scale(gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The scale ``s`` both images are divided by (see module docstring)."""
    gt = _as_stack(gt, "ground truth")
    values = gt if mask is None else gt[np.asarray(mask, bool)]
    scale = float(np.percentile(values, PEAK_PERCENTILE)) if values.size else 0.0
    if not scale > 0:
        scale = float(values.max()) if values.size else 0.0
    if not scale > 0:
        raise SpecGenError("ground-truth image is black inside the mask; PSNR is undefined")
    return scale


def psnr(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
         data_range: float = 1.0) -> float:
    """PSNR (dB) of already-normalised 2-D images over ``mask`` (scikit-image)."""
    from skimage.metrics import peak_signal_noise_ratio

    gt, pred = np.asarray(gt, np.float64), np.asarray(pred, np.float64)
    if mask is not None:
        gt, pred = gt[mask], pred[mask]
    if np.array_equal(gt, pred):
        return float("inf")
    return float(peak_signal_noise_ratio(gt, pred, data_range=data_range))


def ssim(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None,
         data_range: float = 1.0) -> float:
    """SSIM of already-normalised 2-D images, its map averaged over ``mask`` (scikit-image)."""
    from skimage.metrics import structural_similarity

    gt, pred = np.asarray(gt, np.float64), np.asarray(pred, np.float64)
    win = min(7, *gt.shape)
    win -= (win + 1) % 2  # odd window no larger than the image
    if win < 3:
        raise SpecGenError(f"image {gt.shape} is too small for SSIM")
    _, smap = structural_similarity(gt, pred, data_range=data_range, win_size=win, full=True)
    return float(smap[mask].mean() if mask is not None else smap.mean())


def _checked(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None):
    """(gt, pred, mask) as float stacks of one shape and a boolean mask that covers a pixel."""
    gt = _as_stack(gt, "ground truth")
    pred = _as_stack(pred, "prediction")
    if gt.shape != pred.shape:
        raise SpecGenError(f"ground truth {gt.shape} and prediction {pred.shape} differ in shape")
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != gt.shape[:2]:
            raise SpecGenError(f"mask {mask.shape} does not match images {gt.shape[:2]}")
        if not mask.any():
            raise SpecGenError("mask covers no pixel")
    return gt, pred, mask


def _band_psnrs(g: np.ndarray, p: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """PSNR (dB) of each band of already-normalised stacks."""
    return np.array([psnr(g[..., c], p[..., c], mask) for c in range(g.shape[-1])])


def spectral_metrics(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None) -> SpectralMetrics:
    """PSNR and SSIM of ``pred`` against ``gt`` (H, W, C) per band and averaged (module docstring)."""
    gt, pred, mask = _checked(gt, pred, mask)
    scale = normalisation_scale(gt, mask)
    g, p = gt / scale, pred / scale
    ps = _band_psnrs(g, p, mask)
    ss = np.array([ssim(g[..., c], p[..., c], mask) for c in range(g.shape[-1])])
    return SpectralMetrics(ps, ss, float(np.mean(ps)), float(np.mean(ss)), scale)


def _band_mse(g: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Mean squared error of each band (column) of (pixels, Λ) arrays."""
    return np.mean((g - p) ** 2, axis=0)


def _metric_fitted_coefficients(g: np.ndarray, p: np.ndarray, basis: np.ndarray, start_gain: float = 1.0,
                                iterations: int = 30) -> np.ndarray:
    """Coefficients ``c`` of the gain ``basis @ c`` (Λ,) that maximise the *mean band PSNR* of
    ``g`` against ``p · gain`` (both (pixels, Λ), same normalisation), i.e. minimise
    ``Σ_b log MSE_b``; the basis must span the constant gain 1.

    Plain least squares over all bands weighs a bright band's error above a dark one's, while the
    metric weighs every band alike, so a least-squares gain can score *below* the unfitted
    prediction. This minimises the metric itself by majorise–minimise: since
    ``log x ≤ log x₀ + x/x₀ − 1``, each weighted least-squares step with band weights
    ``1 / MSE_b`` (at the current gain) cannot raise ``Σ_b log MSE_b``. It starts from the constant
    gain ``start_gain`` (1: the unfitted prediction), so the result never scores below that start.
    """
    tiny = 1e-300
    c = np.linalg.lstsq(basis, np.full(basis.shape[0], start_gain), rcond=None)[0]   # constant gain

    def objective(coef: np.ndarray) -> float:
        return float(np.sum(np.log(np.maximum(_band_mse(g, p * (basis @ coef)), tiny))))

    # the weighted least-squares step needs only each band's Σ p² and Σ g p (normal equations)
    spp, sgp = np.sum(p * p, axis=0), np.sum(g * p, axis=0)
    best = objective(c)
    for _ in range(iterations):
        w = 1.0 / np.maximum(_band_mse(g, p * (basis @ c)), tiny)                    # (Λ,)
        normal = basis.T @ ((w * spp)[:, None] * basis)
        trial = np.linalg.lstsq(normal, basis.T @ (w * sgp), rcond=None)[0]
        value = objective(trial)
        if not value < best - 1e-12 * max(1.0, abs(best)):
            break
        c, best = trial, value
    return c


def _masked_pixels(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(pixels, Λ) views of the covered pixels, divided by the metric's normalisation scale."""
    scale = normalisation_scale(gt, mask)
    g, p = (gt, pred) if mask is None else (gt[mask], pred[mask])
    return g.reshape(-1, gt.shape[-1]) / scale, p.reshape(-1, gt.shape[-1]) / scale


def _brightness_factor(g: np.ndarray, p: np.ndarray) -> float:
    """The brightness k maximising the mean band PSNR of ``k · p`` against ``g`` ((pixels, Λ))."""
    return float(_metric_fitted_coefficients(g, p, np.ones((g.shape[-1], 1)))[0])


def brightness_fitted_psnr(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float]:
    """(mean PSNR dB, scale k) of ``k · pred`` against ``gt``, k the brightness that maximises it.

    An *oracle* diagnostic (it sees the truth): the part of an error a single exposure factor
    explains, e.g. a photo whose brightness the network cannot know. Same normalisation as
    :func:`spectral_metrics`; k is fitted to the mean band PSNR itself (not to the squared error
    over all bands, which can score below ``pred``), so the result is never below ``pred``'s.
    """
    gt, pred, mask = _checked(gt, pred, mask)
    k = _brightness_factor(*_masked_pixels(gt, pred, mask))
    return mean_psnr(gt, k * pred, mask), k


def colour_fitted_psnr(gt: np.ndarray, pred: np.ndarray, wavelengths_nm: np.ndarray,
                       mask: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """(mean PSNR dB, gain per band) of ``g(λ) · pred`` against ``gt``, ``g`` the smooth spectral
    gain ``g(λ) = Σ_l c_l s_l(λ)`` over Mallett & Yuksel's (2019) three sRGB basis reflectances
    ``s_l`` (wavelengths in nm; held constant beyond 380–780 nm) that maximises the mean band PSNR,
    starting from :func:`brightness_fitted_psnr`'s factor.

    An *oracle* diagnostic like :func:`brightness_fitted_psnr`, one step further: the part of an
    error that one overall colour and brightness explain (a white balance of the whole BRDF), as
    opposed to its angular shape. Same normalisation as :func:`spectral_metrics`; never below the
    brightness fit's score, itself never below ``pred``'s (the basis sums to 1, so every constant
    gain is in its span).
    """
    gt, pred, mask = _checked(gt, pred, mask)
    w = np.asarray(wavelengths_nm, dtype=np.float64).reshape(-1)
    if w.size != gt.shape[-1]:
        raise SpecGenError(f"{w.size} wavelengths for {gt.shape[-1]} bands")
    basis = mallett2019_basis(w)                                                    # (Λ, 3)
    g, p = _masked_pixels(gt, pred, mask)
    k = _brightness_factor(g, p)
    gain = basis @ _metric_fitted_coefficients(g, p, basis, start_gain=k)
    fitted, bright = mean_psnr(gt, pred * gain, mask), mean_psnr(gt, k * pred, mask)
    # the basis sums to 1 only to ~10⁻⁵: where the fit cannot improve, the constant gain is exact
    return (fitted, gain) if fitted >= bright else (bright, np.full_like(gain, k))


def mean_psnr(gt: np.ndarray, pred: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean over bands of PSNR (dB) with :func:`spectral_metrics`' normalisation, without SSIM."""
    gt, pred, mask = _checked(gt, pred, mask)
    scale = normalisation_scale(gt, mask)
    return float(np.mean(_band_psnrs(gt / scale, pred / scale, mask)))

