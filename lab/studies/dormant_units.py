"""How many of a network's ReLU units ever switch on, stage by stage (a dead-unit census).

Feeds the spectral training materials of a config's corpus (their cached lighting-component
stacks, :mod:`specgen_addon.train.lighting_mix`) through the network, canonical input and one
drawn lighting each, and prints :func:`specgen_addon.model.activity.unit_census`.

Usage: ``.venv/bin/python bench/dormant_units.py [--weights W.pt] [--config configs/continue_s19.json] [--n 2023]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from machine import describe_machine  # bench/machine.py

REPO = Path(__file__).resolve().parents[2]


def census_images(config: Path, image_size: int, n: int, seed: int = 0) -> np.ndarray:
    """Canonical inputs of the first ``n`` training materials, then the same under drawn lighting."""
    from latent_distill import training_sets

    from specgen_addon.train.lighting_mix import mix_lighting

    spectral = training_sets(config, image_size)
    stacks = spectral.images[:n]
    rng = np.random.default_rng(seed)
    return np.concatenate([np.stack([s[0] for s in stacks]).astype(np.float32),
                           np.stack([mix_lighting(s, rng, canonical_p=0.0) for s in stacks])])


def main() -> int:
    import torch

    from specgen_addon.model import load_weights
    from specgen_addon.model.activity import unit_census

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", type=Path, default=None, help="weights (.pt); default: shipped")
    ap.add_argument("--config", type=Path, default=REPO / "configs" / "continue_s19.json")
    ap.add_argument("--n", type=int, default=2023, help="training materials (default: all)")
    ap.add_argument("--figure", type=Path, default=None, help="also draw the census as a bar chart (PNG)")
    args = ap.parse_args()
    if args.n < 1:
        ap.error("--n must be ≥ 1")
    torch.set_num_threads(1)
    print("machine:", describe_machine())
    model = load_weights(args.weights)
    images = torch.from_numpy(census_images(args.config, model.cfg.image_size, args.n))
    print(f"weights: {args.weights or 'shipped'}; {images.shape[0] // 2} training materials, canonical "
          f"input and one drawn lighting each ({images.shape[0]} images)")
    print(f"{'stage':28} {'units':>6} {'ever on':>8} {'on per image':>13}")
    stages = unit_census(model, images)
    for s in stages:
        print(f"{s.stage:28} {s.units:6d} {s.ever_active:8d} {s.mean_active:13.1f}")
    if args.figure:
        draw(stages, args.figure, f"{args.weights.name if args.weights else 'shipped weights'}: "
                                  f"{images.shape[0]} training inputs")
        print("figure:", args.figure)
    return 0


def draw(stages, path: Path, title: str) -> None:
    """Horizontal bars per stage: the share of units ever on, and on per image."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [s.stage for s in stages][::-1]
    ever = [100.0 * s.ever_active / s.units for s in stages][::-1]
    per = [100.0 * s.mean_active / s.units for s in stages][::-1]
    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=120)
    y = np.arange(len(names))
    ax.barh(y + 0.2, ever, height=0.4, label="on for some input", color="#4C72B0")
    ax.barh(y - 0.2, per, height=0.4, label="on per input (mean)", color="#DD8452")
    for k, s in enumerate(stages[::-1]):
        ax.text(ever[k] + 1, y[k] + 0.2, f"{s.ever_active} / {s.units}", va="center", fontsize=8)
    ax.set_yticks(y, names)
    ax.set_xlim(0, 115)
    ax.set_xlabel("units of the stage (%); a unit never on is dead: it gets no gradient")
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
