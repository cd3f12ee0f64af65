"""SpecGen core: spectral BRDF generation from a single sphere image (bpy-free).

Implements the method of "SpecGen" (WACV 2026) at CPU size, with the BRDF formats (MERL, RGL),
spectral maths, a synthetic corpus, a reference spectral renderer, the network, and a CLI
(``python -m specgen_addon --help``). Nothing in this package imports ``bpy``; the Blender side
lives in ``ops/``.
"""

__version__ = "0.1.0"
