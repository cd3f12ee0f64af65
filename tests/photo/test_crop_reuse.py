"""A photo cropped twice in one run (the light estimated, then the network) is found once."""

from __future__ import annotations

import os
import warnings

import numpy as np

from specgen_addon.common.image_io import write_png8
from specgen_addon.photo import sphere_image
from specgen_addon.photo.sphere_image import PhotoSource


def _ball(path, shade: float) -> None:
    yy, xx = np.mgrid[0:96, 0:120] + 0.5
    inside = (xx - 60) ** 2 + (yy - 48) ** 2 < 36 ** 2
    img = np.full((96, 120, 3), 0.05 * 255)
    img[inside] = shade * 255
    write_png8(path, np.round(img), overwrite=True)


def test_a_second_crop_of_an_unchanged_photo_is_reused_and_a_changed_photo_is_cropped_again(tmp_path, monkeypatch):
    path = tmp_path / "ball.png"
    _ball(path, 0.6)
    calls = []
    real = sphere_image.load_sphere_crop
    monkeypatch.setattr(sphere_image, "load_sphere_crop", lambda *a, **k: calls.append(a) or real(*a, **k))
    first = PhotoSource(path, circle=(60.0, 48.0, 36.0)).crop()
    again = PhotoSource(path, circle=(60.0, 48.0, 36.0)).crop()
    assert len(calls) == 1
    np.testing.assert_array_equal(first.image, again.image)
    again.image[:] = 0                                          # each caller owns its copy
    assert first.image.max() > 0 and PhotoSource(path, circle=(60.0, 48.0, 36.0)).crop().image.max() > 0

    _ball(path, 0.3)                                             # the photo is replaced on disk
    stamp = path.stat()
    os.utime(path, ns=(stamp.st_atime_ns, stamp.st_mtime_ns + 10 ** 9))
    changed = PhotoSource(path, circle=(60.0, 48.0, 36.0)).crop()
    assert len(calls) == 2
    assert changed.image.max() < first.image.max()


def test_a_reused_crop_says_its_warnings_again(tmp_path, monkeypatch):
    path = tmp_path / "ball.png"
    _ball(path, 0.6)
    real = sphere_image.load_sphere_crop

    def warns(*a, **k):
        warnings.warn("a note about the photo", UserWarning, stacklevel=1)
        return real(*a, **k)

    monkeypatch.setattr(sphere_image, "load_sphere_crop", warns)
    for _ in range(2):
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            PhotoSource(path, circle=(60.0, 48.0, 36.0), white_level=0.9).crop()
        assert [str(w.message) for w in said] == ["a note about the photo"]
