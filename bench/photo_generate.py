"""Generate on a real photo, by default (network, refinement, bake), per way of knowing its light.

    python bench/photo_generate.py [--inputs 0] [--modes given estimated chrome] [--repeat 2]

On the shared grey-ball photos (../shared/data/photos/psm_gray_chrome, ``--linear``, the ball found
in the photo): what the Generate button and ``batch.py`` run, :func:`specgen_addon.generate.lookup.
generate_lookup` at 21 bands and the default lookup size, after the light is resolved by the same
code as ``infer`` (:func:`specgen_addon.cli.photo_args.photo_inputs`):

* ``given``: the dataset's light direction (``--light-vector``);
* ``estimated``: ``--input-env estimate``, lights + ambient fitted to the ball's own shading;
* ``chrome``: ``--light-probe`` the chrome ball under the same lamp (with its mask).

Prints wall and CPU seconds (all threads) per phase: resolving the light, network + refinement,
bake. Targets (2 cores): ≤ 6 s with the light given, ≤ 20 s estimated or from a chrome ball. On a
shared machine the wall time grows with the load (printed); the CPU time much less.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from machine import describe_machine  # bench/machine.py, beside this script

DATA = REPO.parent / "shared" / "data" / "photos" / "psm_gray_chrome"
TARGET_S = {"given": 6.0, "estimated": 20.0, "chrome": 20.0}


def photo_args(mode: str, i: int, tmp: Path) -> list[str]:
    """The ``infer`` options of photo ``i`` under ``mode``."""
    argv = [str(DATA / "gray" / f"gray.{i}.tga"), "-o", str(tmp / "x.npz"), "--linear", "--overwrite"]
    if mode == "given":
        d = np.loadtxt(DATA / "lights.txt", skiprows=1)[i]
        return argv + ["--light-vector", ",".join(f"{v:.6f}" for v in d)]
    if mode == "estimated":
        return argv + ["--input-env", "estimate"]
    return argv + ["--light-probe", str(DATA / "chrome" / f"chrome.{i}.tga"),
                   "--probe-mask", str(DATA / "chrome" / "chrome.mask.tga")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inputs", type=int, nargs="+", default=[0])
    ap.add_argument("--modes", nargs="+", default=["given", "estimated", "chrome"], choices=list(TARGET_S))
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    if not DATA.is_dir():
        print(f"needs the shared photos at {DATA}", file=sys.stderr)
        return 2

    from specgen_addon.cli.app import build_parser
    from specgen_addon.cli.photo_args import photo_inputs
    from specgen_addon.generate.lookup import generate_lookup
    from specgen_addon.spectral.spectra import wavelength_grid

    wl = wavelength_grid(380.0, 780.0, 21)
    tmp = Path(tempfile.mkdtemp(prefix="specgen_photo_bench_"))
    parser = build_parser()
    print(describe_machine())
    with contextlib.redirect_stdout(io.StringIO()):   # warm-up: the model and the scenes load
        ns = parser.parse_args(["infer", *photo_args("given", args.inputs[0], tmp)])
        src, light = photo_inputs(ns, ns.image, tmp / "probe.exr")
        generate_lookup(src, tmp / "lookup", wl, lighting=light, name="warm")
    for i in args.inputs:
        for mode in args.modes:
            walls, cpus = [], []
            for r in range(args.repeat):
                ns = parser.parse_args(["infer", *photo_args(mode, i, tmp)])
                t = [(time.perf_counter(), time.process_time())]
                with contextlib.redirect_stdout(io.StringIO()):
                    src, light = photo_inputs(ns, ns.image, tmp / f"probe{r}.exr")
                t.append((time.perf_counter(), time.process_time()))
                info = generate_lookup(src, tmp / "lookup", wl, lighting=light, name=f"b{i}{mode}{r}")
                t.append((time.perf_counter(), time.process_time()))
                walls.append(t[-1][0] - t[0][0])
                cpus.append(t[-1][1] - t[0][1])
                refine_s = info.refinement.seconds if info.refinement is not None else 0.0
                print(f"gray.{i} {mode:9s} run {r + 1}: {walls[-1]:6.2f} s wall, {cpus[-1]:6.2f} s CPU "
                      f"(light {t[1][0] - t[0][0]:.2f} s; network + refinement + bake "
                      f"{t[2][0] - t[1][0]:.2f} s, of which refinement {refine_s:.2f} s); "
                      f"{info.refinement.summary() if info.refinement is not None else ''}", flush=True)
            print(f"gray.{i} {mode}: median {float(np.median(walls)):.2f} s wall, "
                  f"{float(np.median(cpus)):.2f} s CPU; target ≤ {TARGET_S[mode]:g} s", flush=True)
    print(describe_machine())
    return 0


if __name__ == "__main__":
    sys.exit(main())
