"""Synthetic, physically based spectral BRDF corpus (no bpy).

Public API::

    from specgen_addon.corpus import generate_corpus, load_manifest, save_manifest
    mats = generate_corpus(n=200, seed=0)          # list[Material], each with .split
    f = mats[0].eval(wi, wo, wavelengths_nm)       # (N, Λ) sr⁻¹
    f = mats[0].eval_hd(theta_h, theta_d, phi_d)   # (N, 21) on the default bands
    rgb = mats[0].eval_rgb(wi, wo)                 # (N, 3) linear sRGB under D65
    table = mats[0].tabulate()                     # BRDFTable on the MERL grid
"""

from specgen_addon.corpus.generate import generate_corpus, make_material
from specgen_addon.corpus.manifest import find_material, load_manifest, save_manifest
from specgen_addon.corpus.material import ClearCoat, Conductor, Dielectric, Material, Reflectance
from specgen_addon.corpus.metals import METALS, metal_ior
from specgen_addon.corpus.spectra_sources import METAL_SPLITS, SPLITS

__all__ = ["ClearCoat", "Conductor", "Dielectric", "METALS", "METAL_SPLITS", "Material",
           "Reflectance", "SPLITS", "find_material", "generate_corpus", "load_manifest",
           "make_material", "metal_ior", "save_manifest"]
