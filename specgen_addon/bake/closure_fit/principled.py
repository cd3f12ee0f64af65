"""A Principled BSDF stand-in of a spectral BRDF, for EEVEE, the viewport and other renderers.

Blender's glTF, USD and MaterialX exporters, EEVEE and the viewport understand the Principled BSDF,
not the SpecGen shader. Its parameters are read off the native closure fit
(:class:`~specgen_addon.bake.closure_fit.ClosureFit`, itself fitted to the spectral table), with colours
taken under D65 (linear sRGB, :func:`~specgen_addon.bake.closure_fit.rgb_standin`):

* the broadest strong GGX lobe is the Principled specular layer: its roughness, and its
  normal-incidence reflectance ``F0`` (the lobe's weight plus its Fresnel part at normal
  incidence) set either a metal (base colour = F0, metallic 1) or a dielectric's specular level
  (``F0 = 0.08 · level`` at IOR 1.5) and tint (the lobe's colour), blended between the two by how
  far F0 is above a dielectric's and how weak the diffuse part is;
* the diffuse part is the base colour of a dielectric;
* a second, sharper lobe is the coat (its weight from F0 against the coat's 4 %, its roughness);
* sheen: where the closure fit carries one (:mod:`specgen_addon.bake.closure_fit.sheen`, a fibre
  surface's grazing light), its colour gives the sheen weight (the largest channel) and tint, its
  α the sheen roughness; the Lambert colour fitted with it is the base colour, and only the lobes
  kept beside it make the specular layer and coat. Otherwise the sheen weight is 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from specgen_addon.bake.closure_fit.closures import ClosureFit, fresnel_dielectric, rgb_standin
from specgen_addon.bake.closure_fit.sheen import SheenFit

#: F0 of a dielectric at Principled's default IOR 1.5 and specular level 0.5.
DIELECTRIC_F0 = 0.04
#: F0 from which a lobe counts fully as a metal's.
METAL_F0 = 0.25


@dataclass
class PrincipledFit:
    """Principled BSDF inputs (Blender 4+ names), linear sRGB colours."""

    base_color: tuple[float, float, float]
    metallic: float
    roughness: float
    specular_ior_level: float
    specular_tint: tuple[float, float, float]
    coat_weight: float
    coat_roughness: float
    sheen_weight: float = 0.0
    sheen_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    sheen_roughness: float = 0.5

    def to_dict(self) -> dict:
        return asdict(self)


def _lobes(fit: ClosureFit, which: list[int] | None = None) -> list[tuple[float, np.ndarray]]:
    """(roughness, F0 colour (3,)) of each lobe (those of ``which``, default all), strongest first."""
    rgb = rgb_standin(fit)
    f_normal = float(fresnel_dielectric(np.array([1.0]), fit.ior)[0])
    out = []
    for i, r in enumerate(fit.roughness):
        if which is not None and i not in which:
            continue
        colour = rgb.get(f"Lobe {i + 1}", np.zeros(3)) + f_normal * rgb.get(f"Lobe {i + 1} Fresnel", np.zeros(3))
        out.append((float(np.exp(np.mean(np.log(np.maximum(r, 1e-4))))), np.asarray(colour, np.float64)))
    return sorted(out, key=lambda lobe: -float(lobe[1].max()))


def principled_from_closures(fit: ClosureFit) -> PrincipledFit:
    """The Principled stand-in of a closure fit (module docstring)."""
    rgb = rgb_standin(fit)
    f_normal = float(fresnel_dielectric(np.array([1.0]), fit.ior)[0])
    diffuse = rgb.get("Diffuse", np.zeros(3)) + (1.0 - f_normal) * rgb.get("Diffuse Fresnel", np.zeros(3))
    sheen = None if fit.sheen is None else SheenFit.from_dict(fit.sheen)
    extra = {}
    if sheen is not None:
        diffuse = np.asarray(sheen.diffuse, np.float64)
        peak = max(sheen.colour)
        extra = {"sheen_weight": float(np.clip(peak, 0.0, 1.0)),
                 "sheen_tint": tuple(float(c / peak) for c in sheen.colour),
                 "sheen_roughness": float(np.clip(sheen.roughness, 0.0, 1.0))}
    lobes = _lobes(fit, None if sheen is None else sheen.lobes)
    if not lobes or lobes[0][1].max() <= 0:
        return PrincipledFit(tuple(float(x) for x in np.clip(diffuse, 0, 1)), 0.0, 1.0, 0.0, (1.0, 1.0, 1.0),
                             0.0, 0.0, **extra)
    rough, f0 = lobes[0]
    peak = float(f0.max())
    metal_by_f0 = np.clip((peak - DIELECTRIC_F0) / (METAL_F0 - DIELECTRIC_F0), 0.0, 1.0)
    metallic = float(metal_by_f0 * np.clip(1.0 - diffuse.max() / max(peak, 1e-6), 0.0, 1.0))
    tint = f0 / peak
    base = (1.0 - metallic) * diffuse + metallic * f0
    level = float(np.clip(peak / (2 * DIELECTRIC_F0), 0.0, 1.0)) if metallic < 1 else 0.5
    coat_w, coat_r = 0.0, 0.0
    for r2, c2 in lobes[1:]:
        if r2 < 0.5 * rough and c2.max() > 0.005:
            coat_w, coat_r = float(np.clip(c2.max() / DIELECTRIC_F0, 0.0, 1.0)), r2
            break
    return PrincipledFit(tuple(float(x) for x in np.clip(base, 0.0, 1.0)), metallic, float(np.clip(rough, 0, 1)),
                         level, tuple(float(x) for x in np.clip(tint, 0.0, 1.0)), coat_w,
                         float(np.clip(coat_r, 0, 1)), **extra)
