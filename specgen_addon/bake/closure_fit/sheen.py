"""A sheen layer for the Principled stand-in, fitted where a fibre surface's grazing light needs one.

Felts, velvets and other fibre surfaces reflect more at grazing angles than a Lambert + GGX stack
shows well: the closure fit (:func:`~specgen_addon.bake.closure_fit.fit_closures`) then spends a
very rough lobe on that light, which the Principled stand-in would read as a rough metal. Here
that light is given to the "Charlie" sheen of Estevez & Kulla (2017), "Production Friendly
Microfacet Sheen BRDF", the sheen of glTF's ``KHR_materials_sheen`` (which Blender's glTF
exporter writes from the Principled BSDF's Sheen inputs):

    D(θh) = (2 + 1/α) · sin(θh)^(1/α) / 2π,   V = 1 / [4 (cos θi + cos θo − cos θi cos θo)]
    f_sheen = colour · D · V

with the visibility term of Neubelt & Pettineo (2013). On a grid of direction pairs weighted by
``cos θi cos θo`` (what a render sees), in linear sRGB under D65, the BRDF minus the fit's lobes
sharper than :data:`ROUGH_LOBE` is fitted, per channel and with non-negative weights, by a
Lambert term plus the sheen, for each α of :data:`SHEEN_ROUGHNESS`. The sheen is kept when it
leaves at least :data:`MIN_GAIN` less residual than the Lambert term alone and no more than the
closure fit itself (a rough metal's lobe is not a sheen).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from specgen_addon.bake.closure_fit.closures import ClosureFit, srgb_weights

#: Sheen roughnesses tried (α of the Charlie distribution).
SHEEN_ROUGHNESS = (0.2, 0.3, 0.4, 0.5, 0.7, 1.0)
#: Lobes at least this rough (Blender roughness) may be light that the sheen takes.
ROUGH_LOBE = 0.6
#: Share of the no-sheen residual a sheen must remove to be kept.
MIN_GAIN = 0.25
#: Elevations (radians) and relative azimuths of the fitting grid.
_THETA = np.radians(np.linspace(2.5, 87.5, 18))
_PHI = np.linspace(0.0, np.pi, 13)


@dataclass
class SheenFit:
    """A Principled stand-in's sheen: colour (linear sRGB), Charlie roughness α, the Lambert
    colour fitted with it, and the closure fit's lobes kept beside it (indices)."""

    colour: tuple[float, float, float]
    roughness: float
    diffuse: tuple[float, float, float]
    lobes: list[int] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"colour": list(self.colour), "roughness": self.roughness, "diffuse": list(self.diffuse),
                "lobes": list(self.lobes)}

    @classmethod
    def from_dict(cls, d: dict) -> SheenFit:
        return cls(tuple(float(x) for x in d["colour"]), float(d["roughness"]),
                   tuple(float(x) for x in d["diffuse"]), [int(i) for i in d.get("lobes", [])])


def charlie_sheen(wi: np.ndarray, wo: np.ndarray, alpha: float) -> np.ndarray:
    """The Charlie sheen BRDF (N,) in sr⁻¹ for unit colour at local directions (N, 3) (module docstring)."""
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)
    sin_h = np.sqrt(np.clip(1.0 - h[:, 2] ** 2, 0.0, 1.0))
    d = (2.0 + 1.0 / alpha) * sin_h ** (1.0 / alpha) / (2.0 * np.pi)
    ci, co = np.clip(wi[:, 2], 0.0, 1.0), np.clip(wo[:, 2], 0.0, 1.0)
    v = 1.0 / (4.0 * np.maximum(ci + co - ci * co, 1e-6))
    return np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), d * v, 0.0)


def _grid() -> tuple[np.ndarray, np.ndarray]:
    ti, to, p = np.meshgrid(_THETA, _THETA, _PHI, indexing="ij")
    ti, to, p = ti.ravel(), to.ravel(), p.ravel()
    wi = np.stack([np.sin(ti), np.zeros_like(ti), np.cos(ti)], -1)
    wo = np.stack([np.sin(to) * np.cos(p), np.sin(to) * np.sin(p), np.cos(to)], -1)
    return wi, wo


def _rgb(values: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    m = srgb_weights(wavelengths_nm)
    return values @ m if m is not None else np.repeat(values.mean(axis=1, keepdims=True), 3, axis=1)


def _nonnegative_pair(a: np.ndarray, b: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """(x, z, weighted squared error) of min Σ w (y − x a − z b)² over x, z ≥ 0."""
    aa, bb, ab = np.sum(w * a * a), np.sum(w * b * b), np.sum(w * a * b)
    ay, by = np.sum(w * a * y), np.sum(w * b * y)
    det = aa * bb - ab * ab
    # the corners of the feasible quadrant, and the free minimum when it lies inside
    choices = [(0.0, 0.0)] + ([(max(ay / aa, 0.0), 0.0)] if aa > 0 else []) + ([(0.0, max(by / bb, 0.0))] if bb > 0 else [])
    if det > 1e-12 * aa * bb:
        x, z = (bb * ay - ab * by) / det, (aa * by - ab * ay) / det
        if x >= 0 and z >= 0:
            choices.append((x, z))
    return min(((x, z, float(np.sum(w * (y - x * a - z * b) ** 2))) for x, z in choices), key=lambda c: c[2])


def fit_sheen(evaluate: Callable[[np.ndarray, np.ndarray], np.ndarray], fit: ClosureFit) -> SheenFit | None:
    """The sheen of the Principled stand-in of the BRDF ``evaluate(wi, wo) -> (N, Λ)`` (sr⁻¹ at
    ``fit.wavelengths_nm``) whose closure fit is ``fit``, or None (module docstring)."""
    wi, wo = _grid()
    wl = fit.wavelengths_nm
    target = _rgb(np.asarray(evaluate(wi, wo), np.float64), wl)
    w = wi[:, 2] * wo[:, 2]
    full = float(np.sum(w[:, None] * (target - _rgb(fit.eval(wi, wo), wl)) ** 2))
    rough = [float(np.exp(np.mean(np.log(np.maximum(r, 1e-4))))) for r in fit.roughness]
    keep = [i for i, r in enumerate(rough) if r < ROUGH_LOBE]
    sharp = ClosureFit(wl, np.zeros_like(fit.diffuse), fit.roughness[keep], fit.specular[keep],
                       fit.rel_error, np.zeros_like(fit.diffuse), fit.specular_fresnel[keep], fit.ior)
    rest = target - _rgb(sharp.eval(wi, wo), wl)
    lambert = np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), 1.0 / np.pi, 0.0)
    without = sum(_nonnegative_pair(lambert, np.zeros_like(lambert), rest[:, k], w)[2] for k in range(3))  # no sheen
    best = None
    for alpha in SHEEN_ROUGHNESS:
        s = charlie_sheen(wi, wo, alpha)
        sol = [_nonnegative_pair(lambert, s, rest[:, k], w) for k in range(3)]
        err = sum(c[2] for c in sol)
        if best is None or err < best[0]:
            best = (err, alpha, sol)
    err, alpha, sol = best
    colour = np.array([c[1] for c in sol])
    if colour.max() <= 0 or err > (1.0 - MIN_GAIN) * without or err > full:
        return None
    return SheenFit(tuple(float(c) for c in colour), float(alpha), tuple(float(c[0]) for c in sol), keep)
