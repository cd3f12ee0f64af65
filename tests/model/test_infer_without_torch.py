"""Inside a stock Blender there is no torch: the onnxruntime path must not import it."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import sys
class BlockTorch:
    def find_spec(self, name, path=None, target=None):
        if name == "torch" or name.startswith("torch."):
            raise ImportError("torch is blocked in this test")
        return None
sys.meta_path.insert(0, BlockTorch())
import numpy as np
from specgen_addon.model.runtime.inference import generate_brdf
t = generate_brdf("examples/sphere.png", wavelengths_nm=np.array([450.0, 650.0]), backend="onnx")
assert t.values.shape == (90, 90, 180, 2), t.values.shape
assert np.isfinite(t.values).all() and t.values.min() >= 0
# a photo's sphere (half a pixel off the grid) takes the resampled-input network's graphs
from specgen_addon.photo.sphere_image import load_sphere_image
img = np.pad(load_sphere_image("examples/sphere.png"), ((8, 8), (8, 9), (0, 0)))
off = 0.5 * (img[:, :-1] + img[:, 1:])
r = generate_brdf(off, wavelengths_nm=np.array([550.0]), backend="onnx")
assert r.metadata["weights"].endswith("specgen_resampled.pt") and r.metadata["input_sphere"] == "resampled", r.metadata
assert np.isfinite(r.values).all()
print("ok", float(t.values.mean()))
"""


@pytest.mark.slow
def test_onnx_backend_generates_a_table_with_torch_blocked():
    res = subprocess.run([sys.executable, "-c", SCRIPT], cwd=REPO, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.startswith("ok")


def test_numpy_resample_matches_torch_antialiased_bilinear():
    torch = pytest.importorskip("torch")
    from specgen_addon.model.runtime.inference import resample_square

    rng = np.random.default_rng(0)
    for size_in in (50, 64, 97, 128, 256):
        img = rng.random((size_in, size_in, 3)).astype(np.float32)
        ref = torch.nn.functional.interpolate(
            torch.from_numpy(img.transpose(2, 0, 1).copy())[None], size=(64, 64), mode="bilinear",
            align_corners=False, antialias=True)[0].numpy()
        assert np.abs(resample_square(img, 64) - ref).max() < 1e-5
