"""Make docs/figures/demo.png: the README's demo, with its colour error measured.

    python scripts/make_demo_figure.py [--out out/demo-figure] [--samples 32] [--resolution 256]

Runs ``batch.py`` three times on Suzanne under Blender's ``forest`` map, exactly as
``scripts/demo.sh`` does: from ``examples/sphere.png`` with refinement (the default), the same
without refinement (``--no-refine``, the network alone), and with the true BRDF of the material the
example was rendered from (held-out corpus material ``mat0093``, tabulated on the same grid). Each
spectral EXR's CMF-integrated linear sRGB is compared with the truth's: mean CIEDE2000 over the
object's pixels (colour-science; both normalised by the truth's 99.9th percentile, as the
refinement scores photos). The panels are the sRGB previews; their captions carry the ΔE2000.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

EXAMPLE = REPO / "examples" / "sphere.png"
EXAMPLE_MATERIAL = "mat0093"
ENV = "forest"


def _batch(args: list[str]) -> None:
    cmd = [sys.executable, str(REPO / "batch.py"), "--mesh", "suzanne", "--env", ENV, "--overwrite"] + args
    print("$", " ".join(cmd[1:]), flush=True)
    subprocess.run(cmd, check=True, cwd=REPO)


def _truth_table(path: Path) -> None:
    from specgen_addon.evaluation.protocol import test_materials
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM
    from specgen_addon.brdf.table import BRDFTable

    mat = test_materials(names=[EXAMPLE_MATERIAL])[0]
    wl = DEFAULT_WAVELENGTHS_NM

    def fn(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return mat.eval(wi, wo, wl)

    BRDFTable.tabulate(fn, wl, metadata={"source": f"corpus {EXAMPLE_MATERIAL} (truth)"}).save(path, overwrite=True)


def _srgb_and_alpha(exr: Path) -> tuple[np.ndarray, np.ndarray]:
    from specgen_addon.render.spectral_exr import linear_srgb_preview, read_spectral_exr

    img = read_spectral_exr(exr)
    rgb = linear_srgb_preview(img.values, img.wavelengths_nm)
    mask = np.asarray(img.values).sum(axis=-1) > 0
    return rgb, mask


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "out" / "demo-figure")
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--resolution", type=int, default=256)
    args = ap.parse_args()
    common = ["--samples", str(args.samples), "--resolution", str(args.resolution)]
    runs = {"refined": args.out / "refined", "network": args.out / "network", "truth": args.out / "truth"}
    truth_npz = args.out / f"{EXAMPLE_MATERIAL}_truth.npz"
    args.out.mkdir(parents=True, exist_ok=True)
    _truth_table(truth_npz)
    _batch(["--image", str(EXAMPLE), "--out", str(runs["refined"])] + common)
    _batch(["--image", str(EXAMPLE), "--no-refine", "--out", str(runs["network"])] + common)
    _batch(["--brdf", str(truth_npz), "--out", str(runs["truth"])] + common)

    import colour
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from specgen_addon.render.photo_reproduction import delta_e2000, photo_scale

    exrs = {k: next(d.glob("*.exr")) for k, d in runs.items()}
    truth_rgb, mask = _srgb_and_alpha(exrs["truth"])
    scale = photo_scale(truth_rgb[mask])
    des = {}
    for k in ("network", "refined"):
        rgb, _ = _srgb_and_alpha(exrs[k])
        des[k] = delta_e2000(truth_rgb[mask], rgb[mask], scale)
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.4))
    panels = [("input photo (examples/sphere.png)", plt.imread(EXAMPLE))]
    for k, title in (("network", f"network alone: mean ΔE2000 {des['network']:.2f}"),
                     ("refined", f"refined to the photo: mean ΔE2000 {des['refined']:.2f}"),
                     ("truth", f"true BRDF ({EXAMPLE_MATERIAL})")):
        panels.append((title, plt.imread(exrs[k].with_name(exrs[k].stem + "_preview.png"))))
    for ax, (title, img) in zip(axes, panels):
        ax.imshow(img)
        ax.set_title(title, fontsize=10)
        ax.axis("off")
    fig.tight_layout()
    target = REPO / "docs" / "figures" / "demo.png"
    fig.savefig(target, dpi=90)
    print(f"{target}: ΔE2000 network {des['network']:.3f}, refined {des['refined']:.3f} "
          f"(colour-science {colour.__version__}, {int(mask.sum())} object pixels)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
