"""Generate on a real photo, by default (network, refinement, bake), per way of knowing its light.

    python bench/photo_generate.py [--inputs 0] [--modes given estimated chrome] [--repeat 2]

On the shared grey-ball photos (../shared/data/photos/psm_gray_chrome, ``--linear``, the ball found
in the photo): what the Generate button runs, :func:`specgen_addon.generate.pipeline.generate` with
an ``out_dir`` (network, refinement, bake at 21 bands, the default 180-φd lookup, its preview
image and, as the panel's *Export Table* does by default, the compact material file ``<name>.npz``
(``--no-material-file`` leaves it out); the backend the panel picks: onnx where onnxruntime is
installed; the network at bands 40 nm apart, or with ``--every-band`` at every band), after the
light is resolved by the same code as ``infer`` (:func:`specgen_addon.cli.photo_args.photo_inputs`):

* ``given``: the dataset's light direction (``--light-vector``);
* ``estimated``: ``--input-env estimate``, lights + ambient fitted to the ball's own shading;
* ``chrome``: ``--light-probe`` the chrome ball under the same lamp (with its mask).

Prints wall and CPU seconds (process time, all threads) per phase: resolving the light, the network
(the photo's crop and the network over the table), the refinement, the bake (with the material
file written beside it). Targets (2 cores):
≤ 6 s with the light given, ≤ 20 s estimated or from a chrome ball. The targets are wall times:
compare them on a quiet machine (the load is printed). The CPU time counts every thread, numpy's
and onnxruntime's waiting included, so it is higher on a quiet machine than on a loaded one.
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
PHASES = ("light", "network", "refinement", "bake")


def photo_args(mode: str, i: int, tmp: Path) -> list[str]:
    """The ``infer`` options of photo ``i`` under ``mode``."""
    argv = [str(DATA / "gray" / f"gray.{i}.tga"), "-o", str(tmp / "x.npz"), "--linear", "--overwrite"]
    if mode == "given":
        d = np.loadtxt(DATA / "lights.txt", skiprows=1)[i]
        return argv + ["--light-vector=" + ",".join(f"{v:.6f}" for v in d)]   # "=": a value may start with "-"
    if mode == "estimated":
        return argv + ["--input-env", "estimate"]
    return argv + ["--light-probe", str(DATA / "chrome" / f"chrome.{i}.tga"),
                   "--probe-mask", str(DATA / "chrome" / "chrome.mask.tga")]


def clock() -> np.ndarray:
    """(wall, CPU) seconds now: the CPU clock counts every thread of the process."""
    return np.array([time.perf_counter(), time.process_time()])


class PhaseTimer:
    """Wall and CPU seconds spent inside the pipeline's refinement and bake, wrapped in place (the
    network's share is the rest of :func:`generate`)."""

    def __init__(self, module, names: dict[str, str]):
        self.spent = {phase: np.zeros(2) for phase in names.values()}
        for attr, phase in names.items():
            setattr(module, attr, self._timed(getattr(module, attr), phase))

    def _timed(self, fn, phase: str):
        def run(*args, **kwargs):
            t0 = clock()
            try:
                return fn(*args, **kwargs)
            finally:
                self.spent[phase] += clock() - t0
        return run

    def take(self) -> dict[str, np.ndarray]:
        out = {k: v.copy() for k, v in self.spent.items()}
        for v in self.spent.values():
            v[:] = 0.0
        return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inputs", type=int, nargs="+", default=[0])
    ap.add_argument("--modes", nargs="+", default=["given", "estimated", "chrome"], choices=list(TARGET_S))
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--no-material-file", action="store_true",
                    help="leave out the compact material file the panel writes by default (Export "
                         "Table on), as the figures before 2026-12-07 did")
    ap.add_argument("--every-band", action="store_true",
                    help="the network evaluates every band (Generate's default: bands 40 nm apart)")
    args = ap.parse_args()
    if not DATA.is_dir():
        print(f"needs the shared photos at {DATA}", file=sys.stderr)
        return 2

    from specgen_addon.cli.app import build_parser
    from specgen_addon.cli.photo_args import photo_inputs
    from specgen_addon.generate import pipeline
    from specgen_addon.spectral.spectra import wavelength_grid

    wl = wavelength_grid(380.0, 780.0, 21)
    tmp = Path(tempfile.mkdtemp(prefix="specgen_photo_bench_"))
    parser = build_parser()
    timer = PhaseTimer(pipeline, {"refine_brdf": "refinement", "bake_lookup": "bake"})

    def generate(src, light, name: str):
        return pipeline.generate(src, light, wavelengths_nm=wl, backend=None, out_dir=tmp / "lookup",
                                 name=name, preview=True, every_band=args.every_band,
                                 save_table=not args.no_material_file)

    print(describe_machine())
    print(f"backend: {pipeline.choose_backend()}; the network at "
          + ("every band" if args.every_band else f"bands {pipeline.NETWORK_BAND_GAP_NM:g} nm apart"))
    with contextlib.redirect_stdout(io.StringIO()):   # warm-up: the model and the scenes load
        ns = parser.parse_args(["infer", *photo_args("given", args.inputs[0], tmp)])
        generate(*photo_inputs(ns, ns.image, tmp / "probe.exr"), "warm")
    timer.take()
    for i in args.inputs:
        for mode in args.modes:
            totals = []
            for r in range(args.repeat):
                ns = parser.parse_args(["infer", *photo_args(mode, i, tmp)])
                t0 = clock()
                with contextlib.redirect_stdout(io.StringIO()):
                    src, light = photo_inputs(ns, ns.image, tmp / f"probe{r}.exr")
                t1 = clock()
                info = generate(src, light, f"b{i}{mode}{r}").lookup
                t2 = clock()
                spent = {"light": t1 - t0, **timer.take()}
                spent["network"] = (t2 - t1) - spent["refinement"] - spent["bake"]
                totals.append(t2 - t0)
                phases = "; ".join(f"{p} {spent[p][0]:.2f}/{spent[p][1]:.2f}" for p in PHASES)
                summary = info.refinement.summary() if info.refinement is not None else ""
                print(f"gray.{i} {mode:9s} run {r + 1}: {totals[-1][0]:6.2f} s wall, {totals[-1][1]:6.2f} s CPU "
                      f"(wall/CPU s: {phases}); {summary}", flush=True)
            med = np.median(np.array(totals), axis=0)
            print(f"gray.{i} {mode}: median {med[0]:.2f} s wall, {med[1]:.2f} s CPU; "
                  f"target ≤ {TARGET_S[mode]:g} s", flush=True)
    print(describe_machine())
    return 0


if __name__ == "__main__":
    sys.exit(main())
