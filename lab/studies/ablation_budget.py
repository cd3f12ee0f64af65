"""What a longer budget does to each ablation arm, seed by seed: the score at one budget against another.

Reads two studies written by ``python -m specgen_addon ablate --json`` at different ``--steps``
and, for every (arm, seed) in both, draws a line from its short-budget score to its long-budget
score, one colour per arm; prints the table beside it (scores in dB, network alone, held-out
split, distant lights, as ``ablate`` scores them).

Usage: ``python bench/ablation_budget.py docs/ablation_3000_six_knots.json
docs/ablation_6000_failures.json --figure docs/img/ablation_budget.png``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def scores(path: Path) -> tuple[int, dict[tuple[str, int], float]]:
    """``(steps, {(arm, seed): PSNR dB})`` of one ``ablate --json`` study, its records checked by
    ``ablate``'s own reader (:func:`specgen_addon.evaluation.ablation_study.load_records`)."""
    from specgen_addon.common.errors import SpecGenError
    from specgen_addon.evaluation.ablation_study import load_records

    try:
        steps = json.loads(path.read_text(encoding="utf-8"))["steps"]
        records = load_records(path, steps)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise SystemExit(f"{path}: not an ablate --json study ({e.__class__.__name__}: {e})") from None
    except SpecGenError as e:
        raise SystemExit(str(e)) from None
    return int(steps), {(r["arm"], r["seed"]): r["psnr_distant"] for r in records}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("short", type=Path, help="the study at the shorter budget (ablate --json)")
    ap.add_argument("long", type=Path, help="the study at the longer budget (ablate --json)")
    ap.add_argument("--figure", type=Path, help="PNG to write")
    args = ap.parse_args()
    (n_short, short), (n_long, long) = scores(args.short), scores(args.long)
    both = sorted(set(short) & set(long), key=lambda k: (k[1], k[0]))
    if not both:
        raise SystemExit("the two studies share no (arm, seed)")
    print(f"| arm | seed | {n_short} steps (dB) | {n_long} steps (dB) | change (dB) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for arm, seed in both:
        a, b = short[arm, seed], long[arm, seed]
        print(f"| {arm} | {seed} | {a:.2f} | {b:.2f} | {b - a:+.2f} |")
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        arms = sorted({arm for arm, _ in both})
        fig, ax = plt.subplots(figsize=(4.6, 3.8), dpi=110)
        for arm, seed in both:
            colour = f"C{arms.index(arm)}"
            ax.plot([n_short, n_long], [short[arm, seed], long[arm, seed]], "o-", color=colour, lw=1.2,
                    label=arm if seed == min(s for a, s in both if a == arm) else None)
            ax.annotate(f"seed {seed}", (n_long, long[arm, seed]), xytext=(4, 0), textcoords="offset points",
                        fontsize=7, va="center", color=colour)
        ax.set_xticks([n_short, n_long], [f"{n_short} steps", f"{n_long} steps"])
        ax.set_xlim(n_short - 0.25 * (n_long - n_short), n_long + 0.45 * (n_long - n_short))
        ax.set_ylabel("spectral PSNR (dB), held-out split")
        ax.set_title("each arm and seed at two budgets (from scratch,\nlearning rate halved four times per run)",
                     fontsize=9)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
        fig.tight_layout()
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.figure)
        print(f"wrote {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
