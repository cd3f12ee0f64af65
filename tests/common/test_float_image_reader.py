"""One float image reader (common/image_io.read_float_image) for the photo and the environment map,
each failing with its own error class."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import ImageInputError, SpecGenError
from specgen_addon.common.image_io import read_float_image
from specgen_addon.render.environment import read_hdr_rgb

oiio = pytest.importorskip("OpenImageIO")


def _write(path, pixels: np.ndarray) -> None:
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(pixels.astype(np.float32))
    out.close()


def test_a_radiance_hdr_reads_back_as_its_float_pixels(tmp_path):
    rgb = np.random.default_rng(0).uniform(0.1, 4.0, (6, 8, 3)).astype(np.float32)
    _write(tmp_path / "env.hdr", rgb)
    got = read_float_image(tmp_path / "env.hdr")
    assert got.shape == (6, 8, 3) and got.dtype == np.float32
    # RGBE: 8 bits of mantissa under the pixel's shared exponent, so a step of at most max/128
    assert np.all(np.abs(got - rgb) <= rgb.max(axis=-1, keepdims=True) / 128)
    np.testing.assert_array_equal(read_hdr_rgb(tmp_path / "env.hdr"), got)


@pytest.mark.parametrize("error", [ImageInputError, SpecGenError])
def test_an_unreadable_file_raises_the_callers_error_in_one_sentence(tmp_path, error):
    bad = tmp_path / "broken.hdr"
    bad.write_bytes(b"#?RADIANCE\nnot really\n")
    with pytest.raises(error, match=r"broken\.hdr: cannot read Radiance HDR \(") as info:
        read_float_image(bad, error, "Radiance HDR")
    assert type(info.value) is error and "\n" not in str(info.value)


def test_an_exr_cut_short_after_its_header_is_refused_in_one_line_and_nothing_else(tmp_path, repo_dir):
    """The OpenEXR reader prints its own warning lines about the missing pixels before raising:
    the user reads one sentence, on stderr, and nothing on stdout."""
    import subprocess
    import sys

    cut = tmp_path / "cut.exr"
    cut.write_bytes((repo_dir / "examples" / "sphere.exr").read_bytes()[:5000])   # header, few pixels
    done = subprocess.run([sys.executable, "-m", "specgen_addon", "infer", str(cut), "-o", str(tmp_path / "b.npz"),
                           "--quiet"], capture_output=True, text=True, timeout=120, cwd=repo_dir)
    assert done.returncode == 2 and done.stdout == "", done.stdout
    assert done.stderr.strip().splitlines() == [f"error: {cut}: not a readable OpenEXR file (damaged or cut short)"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut.exr"]
