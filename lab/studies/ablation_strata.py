"""AFF − Hadamard at a long budget, estimated over the seeds of a short-budget study by strata.

The short study (``ablate --json`` at ``--steps`` S, e.g. the 23-seed 3000-step study) splits its
seeds into a *failure* stratum (a seed where either arm scored under ``--failure-below`` dB) and a
*control* stratum (neither did), with population shares n_h / N. The long studies (any number of
``ablate --json`` files at one budget, pooled) give each run seed's paired difference
d = AFF − Hadamard, and :func:`specgen_addon.evaluation.ablation_study.stratified_effect` weighs
each stratum's mean by its share (docs/ablations.md, "Twenty-seventh session": the plan).

Usage::

    python bench/ablation_strata.py --short docs/ablation_3000_six_knots.json --failure-below 26 \\
        --long docs/ablation_6000_failures.json docs/ablation_6000_control.json docs/ablation_6000_s28.json \\
        --figure docs/img/ablation_strata.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))

from ablation_budget import scores  # noqa: E402  (the same reader of `ablate --json` studies)

WITH, WITHOUT = "joint-aff", "joint-hadamard"


def paired(s: dict[tuple[str, int], float]) -> dict[int, float]:
    """AFF − Hadamard for every seed with both arms."""
    seeds = sorted({k[1] for k in s})
    return {seed: s[(WITH, seed)] - s[(WITHOUT, seed)] for seed in seeds
            if (WITH, seed) in s and (WITHOUT, seed) in s}


def main(argv: list[str] | None = None) -> int:
    from specgen_addon.evaluation.ablation_study import stratified_effect

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--short", type=Path, required=True, help="the study whose seeds define the strata")
    ap.add_argument("--failure-below", type=float, required=True, metavar="DB",
                    help="a seed is in the failure stratum when either arm scored under this at the short budget")
    ap.add_argument("--long", type=Path, nargs="+", required=True, help="studies at the long budget (pooled)")
    ap.add_argument("--sign-bar", type=float, default=2.0, metavar="SE")
    ap.add_argument("--json", type=Path, default=None, help="write the estimate and the per-seed table")
    ap.add_argument("--figure", type=Path, default=None, help="PNG: each seed's difference at both budgets")
    args = ap.parse_args(argv)

    short_steps, short = scores(args.short)
    d_short = paired(short)
    failed = {seed for (arm, seed), v in short.items() if v < args.failure_below and seed in d_short}
    stratum = {seed: "failure" if seed in failed else "control" for seed in d_short}
    long: dict[tuple[str, int], float] = {}
    long_steps = None
    for path in args.long:
        steps, s = scores(path)
        if long_steps not in (None, steps):
            raise SystemExit(f"{path}: {steps} steps, but the other long studies have {long_steps}")
        long_steps = steps
        for k, v in s.items():
            if k in long and abs(long[k] - v) > 0.005:
                raise SystemExit(f"{path}: {k[0]} seed {k[1]} scores {v:.3f}, another study {long[k]:.3f}")
            long[k] = v
    d_long = paired(long)
    outside = sorted(set(d_long) - set(stratum))
    if outside:
        raise SystemExit(f"seeds {outside} are not in the short study, so they have no stratum")
    n_all = len(stratum)
    strata = {h: (sum(1 for v in stratum.values() if v == h) / n_all,
                  [d_long[seed] for seed in sorted(d_long) if stratum[seed] == h]) for h in ("failure", "control")}
    result = stratified_effect(strata, sign_bar=args.sign_bar)

    print(f"| seed | stratum ({short_steps} steps) | AFF − Hadamard at {short_steps} (dB) | "
          f"AFF / Hadamard at {long_steps} (dB) | **d at {long_steps} (dB)** |")
    print("| ---: | --- | ---: | ---: | ---: |")
    for seed in sorted(d_long, key=lambda s: (stratum[s], s)):
        print(f"| {seed} | {stratum[seed]} | {d_short[seed]:+.2f} | {long[(WITH, seed)]:.2f} / "
              f"{long[(WITHOUT, seed)]:.2f} | **{d_long[seed]:+.2f}** |")
    print()
    for h, r in result["strata"].items():
        n_h = round(r["share"] * n_all)
        print(f"{h}: share {n_h}/{n_all}, {r['n']} seeds at {long_steps} steps, mean {r['mean']:+.2f} dB, "
              f"std {r['std']:.2f} dB")
    print(f"stratified estimate {result['estimate']:+.2f} dB, standard error {result['se']:.2f} "
          f"(z {result.get('z', float('nan')):.2f}); sign at {args.sign_bar:g} SE: {result['sign']}")
    print(f"beside it, deciding nothing: Welch–Satterthwaite df {result['df']:.1f}, t-based 95 % interval "
          f"[{result['ci95'][0]:+.2f}, {result['ci95'][1]:+.2f}] dB")
    if args.json is not None:
        args.json.write_text(json.dumps({"short_steps": short_steps, "long_steps": long_steps,
                                         "failure_below": args.failure_below,
                                         "strata_of_seeds": {str(k): v for k, v in sorted(stratum.items())},
                                         "d_short": {str(k): v for k, v in sorted(d_short.items())},
                                         "d_long": {str(k): v for k, v in sorted(d_long.items())},
                                         **result}, indent=1), encoding="utf-8")
    if args.figure is not None:
        plot(args.figure, d_short, d_long, stratum, result, short_steps, long_steps)
    return 0


def plot(path: Path, d_short: dict[int, float], d_long: dict[int, float], stratum: dict[int, str],
         result: dict, short_steps: int, long_steps: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"failure": "tab:red", "control": "tab:blue"}
    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=110)
    for seed, d in d_short.items():
        ax.scatter(0, d, s=14, color=colours[stratum[seed]], alpha=0.35)
    label_at = -1e9
    for seed, d in sorted(d_long.items(), key=lambda kv: kv[1]):
        ax.plot([0, 1], [d_short[seed], d], color=colours[stratum[seed]], lw=1)
        ax.scatter(1, d, s=22, color=colours[stratum[seed]])
        label_at = max(d, label_at + 0.32)  # seeds with near-equal differences get stacked labels
        ax.annotate(f"seed {seed}", (1, d), xytext=(1.04, label_at), fontsize=7, va="center")
    est, se = result["estimate"], result["se"]
    if est == est:
        ax.errorbar(1.35, est, yerr=2 * se, fmt="D", color="black", capsize=4,
                    label=f"stratified estimate ± 2 SE: {est:+.2f} ± {2 * se:.2f} dB")
    for h, c in colours.items():
        ax.scatter([], [], color=c, label=f"{h} stratum")
    ax.axhline(0, color="grey", lw=0.8, ls=":")
    ax.set_xticks([0, 1, 1.35], [f"{short_steps} steps\n(all seeds)", f"{long_steps} steps", "estimate"])
    ax.set_xlim(-0.3, 1.6)
    ax.set_ylabel("AFF − Hadamard (dB, network alone)")
    ax.set_title("AFF − Hadamard by seed, strata from the short budget", fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
