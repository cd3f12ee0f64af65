"""Training curves of several runs on one figure: smoothed training loss and validation μ-law MSE.

Each run is ``LABEL=RUN_DIR`` (the folder holding the run's ``history.csv``). ``--reference``
draws a horizontal line at a validation MSE to beat (e.g. the shipped weights').

Usage: ``python bench/compare_runs.py fresh=out/s25/fresh warm=out/s25/warm --reference 7.6e-4
--reference-label "run19 level (≈7.6e-4)" --figure docs/img/encoder_runs_s25.png``
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np


def read_history(run_dir: Path) -> tuple[np.ndarray, np.ndarray, list[tuple[int, float]]]:
    """``(steps, training loss, [(step, validation MSE)])`` from ``run_dir/history.csv``."""
    with open(run_dir / "history.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit(f"{run_dir}/history.csv: no steps recorded")
    steps = np.array([int(r["step"]) for r in rows])
    loss = np.array([float(r["loss"]) for r in rows])
    val = [(int(r["step"]), float(r["val"])) for r in rows if r.get("val")]
    return steps, loss, val


def smooth(x: np.ndarray, window: int) -> np.ndarray:
    """Running mean over the last ``window`` steps (fewer at the start)."""
    c = np.cumsum(np.insert(x, 0, 0.0))
    i = np.arange(1, x.size + 1)
    lo = np.maximum(i - window, 0)
    return (c[i] - c[lo]) / (i - lo)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="LABEL=RUN_DIR")
    ap.add_argument("--window", type=int, default=500, help="steps in the training-loss running mean")
    ap.add_argument("--reference", type=float, default=None, help="a validation MSE to draw as a line")
    ap.add_argument("--reference-label", default="reference", help="legend text of that line")
    ap.add_argument("--figure", type=Path, required=True, help="PNG to write")
    args = ap.parse_args()
    runs = []
    for spec in args.runs:
        label, sep, path = spec.partition("=")
        if not sep or not label or not Path(path, "history.csv").is_file():
            ap.error(f"{spec!r}: expected LABEL=RUN_DIR with a history.csv in it")
        runs.append((label, Path(path)))
    if args.window < 1:
        ap.error("--window must be ≥ 1")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), dpi=110)
    for label, path in runs:
        steps, loss, val = read_history(path)
        line, = a.plot(steps, smooth(loss, args.window), lw=1.2, label=label)
        if val:
            b.plot(*zip(*val), "o-", ms=3, color=line.get_color(), label=label)
        print(f"{label}: {steps[-1]} steps, last {args.window}-step mean loss {loss[-args.window:].mean():.3e}, "
              f"last validation {val[-1][1]:.3e}" if val else f"{label}: {steps[-1]} steps")
    if args.reference is not None:
        b.axhline(args.reference, color="k", ls="--", lw=1, label=args.reference_label)
    for ax, title in ((a, f"training loss ({args.window}-step mean)"), (b, "validation μ-law MSE")):
        ax.set_yscale("log")
        ax.set_xlabel("step")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.tight_layout()
    args.figure.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.figure)
    print("figure:", args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
