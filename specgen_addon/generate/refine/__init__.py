"""Photo-consistent refinement: analysis by synthesis after the network.

:func:`refine_brdf` (:mod:`.refinement`) corrects the network's table until it reproduces the photo
under its lighting: the rendering operator (:mod:`.operator`), the correction basis (:mod:`.basis`),
the diffuse body (:mod:`.body`), the photo's blur (:mod:`.blur`), the solve (:mod:`.solve`) and
the hold-out checks (:mod:`.holdout`, :mod:`.discrepancy`).
"""

from specgen_addon.generate.refine.basis import CorrectionBasis
from specgen_addon.generate.refine.operator import PhotoOperator
from specgen_addon.generate.refine.refinement import (
                                                      CLIP_LEVEL,
                                                      WARN_PSNR_DB,
                                                      RefineOptions,
                                                      RefineResult,
                                                      apply_correction,
                                                      diffuse_floor_of,
                                                      refine_brdf,
                                                      render_under,
                                                      theta_d_seen,
)
from specgen_addon.render.photo_reproduction import Reproduction

__all__ = ["CLIP_LEVEL", "WARN_PSNR_DB", "CorrectionBasis", "PhotoOperator", "RefineOptions", "RefineResult",
           "Reproduction", "apply_correction", "diffuse_floor_of", "refine_brdf", "render_under", "theta_d_seen"]
