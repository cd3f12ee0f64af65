"""How long a whole-scene spectral render will take, told before it starts.

A Cycles render costs roughly ``overhead + rate × pixels × samples``: the overhead (scene sync,
BVH, kernels, image handling) does not grow with the image, the rest does. Two tiny test renders
of the scene itself at the same size with different sample counts separate the two
(:func:`fit_cost`); the stack then costs that per band group (:meth:`RenderCost.predict`).
With adaptive sampling on, a third tiny render at the scene's own sample count measures the share
of samples it really takes (:meth:`RenderCost.with_adaptive`). With denoising on, two more
one-sample renders with the scene's denoiser, at two sizes, give the denoiser's cost per render
and per pixel (it does not depend on the samples; :meth:`RenderCost.with_denoising`). Persistent
data only makes the real render faster, so the figure leans high.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from specgen_addon.common.errors import SpecGenError


@dataclass(frozen=True)
class RenderCost:
    """``overhead_s`` per render and ``rate_s`` per pixel-sample, measured on this machine;
    ``sample_fraction``: the share of the samples adaptive sampling actually takes (1: all);
    ``denoise_overhead_s`` per denoised render and ``denoise_rate_s`` per denoised pixel (0: not
    measured, the scene does not denoise)."""

    overhead_s: float
    rate_s: float
    sample_fraction: float = 1.0
    denoise_overhead_s: float = 0.0
    denoise_rate_s: float = 0.0

    def render_s(self, pixels: int, samples: int) -> float:
        """Seconds of one render of ``pixels`` pixels at ``samples`` samples per pixel."""
        return self.overhead_s + self.rate_s * float(pixels) * float(samples) * self.sample_fraction

    def with_adaptive(self, pixels: int, samples: int, seconds: float) -> RenderCost:
        """This cost with the sample share of adaptive sampling, from one render of ``pixels``
        pixels with adaptive sampling up to ``samples`` that took ``seconds``."""
        full = self.rate_s * pixels * samples
        share = (seconds - self.overhead_s) / full if full > 0 else 1.0
        return replace(self, sample_fraction=float(min(max(share, 0.01), 1.0)))

    def denoise_s(self, pixels: int) -> float:
        """Seconds the denoiser adds to one render of ``pixels`` pixels."""
        return self.denoise_overhead_s + self.denoise_rate_s * float(pixels)

    def with_denoising(self, pixels: tuple[int, int], seconds: tuple[float, float]) -> RenderCost:
        """This cost with the denoiser's, from two one-sample renders with denoising of
        ``pixels`` pixels (two sizes) that took ``seconds``; the same renders without denoising
        are this model's."""
        (p1, p2), (t1, t2) = pixels, seconds
        if p1 == p2 or min(p1, p2) <= 0:
            raise SpecGenError("the denoising estimate needs test renders of two sizes")
        extra1, extra2 = (max(t - self.render_s(p, 1), 0.0) for p, t in ((p1, t1), (p2, t2)))
        rate = max((extra2 - extra1) / (p2 - p1), 0.0)
        rate = rate or max(extra1, extra2) / max(p1, p2)   # timer noise: all of it per pixel
        overhead = max(extra1 - rate * p1, 0.0)
        return replace(self, denoise_overhead_s=overhead, denoise_rate_s=rate)

    def predict(self, renders: int, pixels: int, samples: int, denoised: int = 0) -> float:
        """Seconds of ``renders`` renders (one per band group) of the same size and samples,
        ``denoised`` of them with the denoiser."""
        return renders * self.render_s(pixels, samples) + denoised * self.denoise_s(pixels)


def fit_cost(pixels: int, samples: tuple[int, int], seconds: tuple[float, float]) -> RenderCost:
    """The cost model from two renders of ``pixels`` pixels at two sample counts."""
    (s1, s2), (t1, t2) = samples, seconds
    if s2 <= s1 or pixels <= 0:
        raise SpecGenError("the time estimate needs two test renders with rising sample counts")
    rate = max((t2 - t1) / (pixels * (s2 - s1)), 0.0)
    rate = rate or t2 / (pixels * s2)              # timer noise: charge it all to the samples
    return RenderCost(overhead_s=max(t1 - rate * pixels * s1, 0.0), rate_s=rate)


def format_duration(seconds: float) -> str:
    """``"45 s"``, ``"3.5 min"``, ``"2.1 h"``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"
