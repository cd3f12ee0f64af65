"""White balance from an X-Rite ColorChecker Classic in the photo (command line only).

The chart is found by colour-science's ``colour-checker-detection`` (segmentation, OpenCV), on the
photo's linear values: the detector encodes them to sRGB itself to find the swatches, and samples
the swatches' linear colours. Its choice of the chart's orientation compares raw values with the
reference and fails under a strong cast or exposure, so the four orientations of each chart found
are scored here by how well the bottom row fits the reference greys with one gain per channel (a
cast and an exposure leave that fit exact; a wrong orientation does not). The gains are then the
least-squares fit of the six greys (those free of saturated pixels) to the reference chart's greys
in linear sRGB under the light the run assumes (``target``: neutral for D65, warm under a 3200 K
lamp, as :mod:`specgen_addon.photo.white_balance`), the photo's luminance kept.

The reference is colour-science's ``ColorChecker24 - After November 2014`` (xyY under D50, adapted
to sRGB's D65 by CAT02). ``colour`` and ``colour_checker_detection`` are imported when a chart is
looked for: a stock Blender has neither (no OpenCV), and the panel never asks for one.
"""

from __future__ import annotations

import warnings
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from specgen_addon.common.errors import ImageInputError
from specgen_addon.photo.image_checks import ImageNote
from specgen_addon.photo.white_balance import LUMINANCE

#: colour-science's name of the chart's reference (X-Rite's values since November 2014).
CHART = "ColorChecker24 - After November 2014"
#: The six greys: the chart's bottom row, white to black (swatch numbers 19 to 24).
GREYS = slice(18, 24)
#: Above this rms difference between the balanced greys and the reference (a share of the mean
#: reference grey) the greys do not follow the chart: a wrong encoding, flare or a shadow on it.
GREY_FIT_WARN = 0.05
#: Fewest greys free of saturated pixels that still give a balance.
MIN_GREYS = 2
_NEED = ("--colour-checker needs the colour-checker-detection package (with OpenCV), which the command "
         "line has and a stock Blender does not")
_FOUND: OrderedDict = OrderedDict()   # a photo's key → its chart found (one detection per run)


def reference_swatches() -> np.ndarray:
    """The chart's 24 swatches (24, 3) in linear sRGB (D65), row by row from dark skin to black."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import colour
    except ImportError:
        raise ImageInputError(_NEED) from None
    chart = colour.CCS_COLOURCHECKERS[CHART]
    xyy = np.array(list(chart.data.values()), np.float64)
    return np.asarray(colour.XYZ_to_RGB(colour.xyY_to_XYZ(xyy), "sRGB", chart.illuminant), np.float64)


@dataclass(frozen=True)
class CheckerFound:
    """A chart in a photo: its 24 swatches' mean linear colours as shot (24, 3), the share of each
    swatch's sampled pixels that are saturated (24,), its corners (4, 2; pixels of the file, x right,
    y down) and how many charts the photo held."""

    swatches: np.ndarray
    saturated: np.ndarray
    corners: np.ndarray
    count: int = 1


@dataclass(frozen=True)
class CheckerBalance:
    """The white balance a chart gives: gains (3,), the greys used (indices into the six), the
    rms difference of the balanced greys from the reference after one exposure factor (a share of
    the mean reference grey), and the chart it came from."""

    gains: np.ndarray
    used: tuple[int, ...]
    fit_rms: float
    found: CheckerFound

    def describe(self) -> str:
        """One line for a run's report: where the chart is, its greys as shot, the fit."""
        c = self.found.corners
        centre = c.mean(axis=0)
        width = max(np.linalg.norm(c[1] - c[0]), np.linalg.norm(c[2] - c[1]))
        greys = self.found.swatches[GREYS]
        shot = ", ".join("{:.3f}/{:.3f}/{:.3f}".format(*greys[i]) for i in range(6))
        left = [i + 19 for i in range(6) if i not in self.used]
        out = (f"colour checker: a ColorChecker Classic at ({centre[0]:.0f}, {centre[1]:.0f}) px, "
               f"{width:.0f} px wide, 24 swatches sampled; its greys as shot (linear R/G/B, white to "
               f"black) {shot}; {len(self.used)} fitted to the reference greys to {100 * self.fit_rms:.1f} % rms")
        if left:
            out += f" (swatch {', '.join(map(str, left))} saturated, left out)"
        if self.found.count > 1:
            out += f"; {self.found.count} charts in the photo, the best fitting one used"
        return out


def _fit(greys: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-channel least-squares gains (3,) taking ``greys`` (n, 3) to ``reference`` (n, 3), and the
    rms difference left, a share of the reference's mean."""
    gains = (greys * reference).sum(axis=0) / np.maximum((greys * greys).sum(axis=0), 1e-30)
    rms = float(np.sqrt(np.mean((greys * gains - reference) ** 2)) / max(float(reference.mean()), 1e-30))
    return gains, rms


def _usable(found_swatches: np.ndarray, saturated: np.ndarray) -> list[int]:
    greys = found_swatches[GREYS]
    return [i for i in range(6) if saturated[GREYS][i] == 0 and np.all(greys[i] > 0)]


def _orientation_score(swatches: np.ndarray, saturated: np.ndarray, reference: np.ndarray) -> float:
    used = _usable(swatches, saturated)
    if len(used) < MIN_GREYS:
        return np.inf
    return _fit(swatches[GREYS][used], reference[GREYS][used])[1]


def _to_file_pixels(quad: np.ndarray, shape: tuple[int, int], work_width: int, scale: float) -> np.ndarray:
    """The detector's corners (pixels of the image resized to ``work_width`` wide, turned a quarter
    clockwise when the photo is portrait) → pixels of the file."""
    height, width = shape
    long_side = max(width, height)
    q = np.asarray(quad, np.float64) * (long_side / work_width)
    if width < height:    # undo cv2.ROTATE_90_CLOCKWISE: (x', y') = (H - y, x)
        q = np.stack([q[:, 1], height - q[:, 0]], axis=1)
    return q / scale


def find_checker(rgb: np.ndarray, saturated: np.ndarray | None, scale: float = 1.0,
                 key: object = None) -> CheckerFound:
    """The ColorChecker Classic in a linear photo ``rgb`` (H, W, 3+); ``saturated`` (H, W) marks
    clipped pixels; ``scale`` is the read image's width over the file's. ``key`` (hashable, e.g. the
    file and its decoding) keeps the chart found for the run's later reads of the same photo."""
    if key is not None and key in _FOUND:
        return _FOUND[key]
    try:
        with warnings.catch_warnings():   # its plotting stack's deprecation notes are not the run's
            warnings.simplefilter("ignore")
            import cv2
            from colour_checker_detection import (
                SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC,
                detect_colour_checkers_segmentation,
            )
            from colour_checker_detection.detection.common import reformat_image, sample_colour_checker
    except ImportError:
        raise ImageInputError(_NEED) from None
    reference = reference_swatches()
    img = np.nan_to_num(np.asarray(rgb[..., :3], np.float32))
    level = float(np.percentile(img.max(axis=-1), 99.5))
    img = img / (level if level > 0 else 1.0)          # the detector thresholds an sRGB encoding of [0, 1]
    sat = np.zeros(img.shape[:2], np.float32) if saturated is None else np.asarray(saturated, np.float32)
    settings = dict(SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC, reference_values=None)
    work_w = int(settings["working_width"])
    rectangle = np.array([[work_w, 0], [work_w, int(work_w / settings["aspect_ratio"])],
                          [0, int(work_w / settings["aspect_ratio"])], [0, 0]], np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # its note that it cannot orient the chart: done below
        charts = detect_colour_checkers_segmentation(img, additional_data=True, reference_values=None)
        work = reformat_image(img, work_w, settings["interpolation_method"])
        work_sat = reformat_image(np.repeat(sat[..., None], 3, axis=-1), work_w, cv2.INTER_LINEAR)
        best = None
        for chart in charts:
            for turn in range(4):
                quad = np.roll(np.asarray(chart.quadrilateral, np.float32), turn, axis=0)
                swatches = sample_colour_checker(work, quad, rectangle, **settings).swatch_colours
                clipped = sample_colour_checker(work_sat, quad, rectangle, **settings).swatch_colours[:, 0]
                score = _orientation_score(np.asarray(swatches, np.float64), clipped, reference)
                if best is None or score < best[0]:
                    best = (score, swatches, clipped, quad)
    if best is None:
        raise ImageInputError("no colour checker found in the photo: --colour-checker needs an X-Rite "
                              "ColorChecker Classic (24 swatches) in the frame, whole, facing the camera "
                              "and at least about a tenth of the photo's width")
    _, swatches, clipped, quad = best
    found = CheckerFound(np.asarray(swatches, np.float64) * (level if level > 0 else 1.0),
                         np.asarray(clipped, np.float64),
                         _to_file_pixels(quad, img.shape[:2], work_w, scale), len(charts))
    if key is not None:
        _FOUND[key] = found
        while len(_FOUND) > 4:
            _FOUND.popitem(last=False)
    return found


def checker_balance(found: CheckerFound, target: tuple[float, float, float] | None = None) -> CheckerBalance:
    """The gains that take the chart's greys to the reference greys under ``target`` (linear RGB, the
    colour of a white surface under the run's light; default neutral), the greys' luminance kept.
    Fewer than :data:`MIN_GREYS` greys free of saturation is refused in one sentence."""
    used = _usable(found.swatches, found.saturated)
    if len(used) < MIN_GREYS:
        raise ImageInputError(f"the colour checker's greys are saturated or black ({len(used)} of 6 usable): "
                              "expose so the chart's white is below clipping")
    goal = np.ones(3) if target is None else np.asarray(target, np.float64)
    if goal.shape != (3,) or not np.all(goal > 0):
        raise ImageInputError(f"the white balance target must be a positive RGB colour, got {target}")
    greys = found.swatches[GREYS][used]
    reference = reference_swatches()[GREYS][used] * (goal / float(goal @ LUMINANCE))
    gains, _ = _fit(greys, reference)
    gains = gains * float((greys @ LUMINANCE).sum() / ((greys * gains) @ LUMINANCE).sum())
    balanced = greys * gains
    exposure = float((balanced @ LUMINANCE).sum() / (reference @ LUMINANCE).sum())
    rms = float(np.sqrt(np.mean((balanced - exposure * reference) ** 2)) / (exposure * reference.mean()))
    result = CheckerBalance(gains, tuple(used), rms, found)
    if rms > GREY_FIT_WARN:
        warnings.warn(f"the colour checker's greys differ from the reference by {100 * rms:.0f} % rms after "
                      "the balance: check the photo's encoding (--linear), flare or a shadow on the chart",
                      ImageNote, stacklevel=2)
    return result
