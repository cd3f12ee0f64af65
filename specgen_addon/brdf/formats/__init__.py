"""BRDF file formats: MERL ``.binary``, RGL ``.bsdf`` and SpecGen tables (``.npz``).

:func:`load_brdf` (:mod:`.load`) dispatches on the file's magic bytes (not only its suffix) and
returns an object following the BRDF protocol: ``eval(wi, wo, wavelengths_nm)`` /
``eval_rgb(wi, wo)``; :func:`tabulate_file` puts any of them on the MERL grid.
"""

from specgen_addon.brdf.formats.load import detect_format, load_brdf, tabulate_file

__all__ = ["detect_format", "load_brdf", "tabulate_file"]
