"""Seeded ablation study (paper §4.4): AFF vs Hadamard fusion, joint vs spectral-only training.

Each arm of :mod:`.ablation` is trained from scratch with several seeds at one equal step budget and
scored, network alone, on the held-out mixed test split under the protocol's distant lights (the
per-family measure of :func:`.trained_network.evaluate_families`: spectral PSNR in dB, first
``per_family`` test materials of each corpus family). An effect is the per-seed *paired* difference
of two arms (the same seed gives both arms the same spectral batches), reported as mean ± sample
standard deviation over seeds with its standard error; its sign is called only when the mean is at
least ``sign_bar`` standard errors from zero (two by default; more for a study that has been looked
at, and extended, before: Pocock's constant for the number of looks). A Wilcoxon signed-rank test
and each arm's count of failed runs (scores under ``failure_below`` dB) are reported beside it and
decide nothing.

Arms train in separate processes (one torch thread each), so ``workers`` arms run at once on as
many cores. Trained arms and their scores are cached under ``cache_root()/ablation``: a rerun
trains and scores nothing it finds there, and a stopped run resumes from the arms' checkpoints.
"""

from __future__ import annotations

import dataclasses
import math
import signal
import textwrap
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from specgen_addon.evaluation import ablation as abl
from specgen_addon.common.cache import cache_root, read_json, write_json
from specgen_addon.common.errors import SpecGenError
from specgen_addon.evaluation.ablation import ARMS_BY_NAME

#: Arms of the study: the shipped configuration (joint AFF) and one change each.
STUDY_ARMS = ("joint-aff", "joint-hadamard", "spectral-aff")
STUDY_SEEDS = (0, 1, 2)
#: (effect label, arm with the paper's component, arm without it).
EFFECTS = (("AFF − Hadamard (joint training)", "joint-aff", "joint-hadamard"),
           ("joint − spectral-only (AFF)", "joint-aff", "spectral-aff"))
PER_FAMILY = 3
RESOLUTION = 64
#: The default bar for calling an effect's sign, in standard errors of the paired mean.
SIGN_BAR_SE = 2.0


def study_settings(steps: int, seeds: Sequence[int] = STUDY_SEEDS,
                   arms: Sequence[str] = STUDY_ARMS) -> abl.AblationSettings:
    """Equal-budget settings of the shipped model's configuration, trained from scratch."""
    model, train_d = abl._default_configs()
    return abl.AblationSettings(steps=int(steps), seeds=tuple(int(s) for s in seeds), arms=tuple(arms),
                                model=model, train=train_d, budget_note="(step budget given)")


def _score_path(arm_dir: Path, per_family: int, resolution: int) -> Path:
    return arm_dir / f"score_f{per_family}_r{resolution}.json"


def run_arm(settings: abl.AblationSettings, arm: str, seed: int, cache_dir: str,
            per_family: int = PER_FAMILY, resolution: int = RESOLUTION) -> dict[str, Any]:
    """Train (or load) one arm with one seed and score it; a JSON-able record."""
    import torch

    from specgen_addon.evaluation.trained_network import evaluate_families

    torch.set_num_threads(1)
    one = dataclasses.replace(settings, seeds=(seed,), arms=(arm,))
    res = abl.train_arms(one, Path(cache_dir), progress=False, log=lambda s: None)[f"{arm}/seed{seed}"]
    score_path = _score_path(res.weights.parent, per_family, resolution)
    score = read_json(score_path)
    if score is None:
        ev = evaluate_families(weights=res.weights, per_family=per_family, envs=False, resolution=resolution,
                               self_reproduction=False)  # the arms compare PSNR only
        score = {"psnr_distant": ev["means"]["psnr_distant"], "ssim_distant": ev["means"]["ssim_distant"],
                 "families": {f: s["psnr_distant"] for f, s in ev["families"].items()}}
        write_json(score_path, score)
    return {"arm": arm, "seed": seed, "key": res.key, "steps": res.steps, "wall_seconds": res.wall_seconds,
            **score}


def prepare_data(settings: abl.AblationSettings, jobs: Sequence[tuple[str, int]], cache_dir: Path,
                 log: Callable[[str], None] = print) -> None:
    """Render the training inputs that the arms still to train need, here, with the configured
    render workers: an arm's own process is a pool worker, which cannot start render workers of
    its own, so it then finds every render in the shared cache instead of making them one by one."""
    seen: set[str] = set()
    for name, seed in jobs:
        arm = abl.ARMS_BY_NAME[name]
        arm_dir = Path(cache_dir) / settings.key(arm, seed)
        if (arm_dir / "arm.json").is_file() and (arm_dir / "specgen.pt").is_file():
            continue
        mcfg, tcfg = settings.configs(arm, seed)
        ident = repr(({**mcfg.to_dict(), "fusion": None}, dataclasses.replace(tcfg, seed=0)))
        if ident not in seen:
            seen.add(ident)
            abl._material_sets(tcfg, mcfg, abl._data_cache(), log)


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_study(steps: int, seeds: Sequence[int] = STUDY_SEEDS, arms: Sequence[str] = STUDY_ARMS,
              workers: int = 2, per_family: int = PER_FAMILY, resolution: int = RESOLUTION,
              cache_dir: Path | None = None, log: Callable[[str], None] = print, sign_bar: float = SIGN_BAR_SE,
              failure_below: float | None = None) -> dict[str, Any]:
    """Train and score every (arm, seed); returns the records and the summary of :func:`summarise`
    (signs called at ``sign_bar`` standard errors, failed runs counted under ``failure_below`` dB)."""
    settings = study_settings(steps, seeds, arms)
    cache = Path(cache_dir) if cache_dir is not None else cache_root() / "ablation"
    jobs = [(a, s) for s in settings.seeds for a in settings.arms]
    records: list[dict[str, Any]] = []
    if workers <= 1:
        for a, s in jobs:
            records.append(run_arm(settings, a, s, str(cache), per_family, resolution))
            log(f"ablate: {a} seed {s}: {records[-1]['psnr_distant']:.2f} dB")
    else:
        # Workers ignore Ctrl-C: the parent takes it (a clean stop) and ends them; a stopped arm
        # keeps its last checkpoint in the cache, and the next run resumes it.
        prepare_data(settings, jobs, cache, log)
        pool = get_context("spawn").Pool(workers, initializer=_ignore_sigint)
        try:
            pending = [pool.apply_async(run_arm, (settings, a, s, str(cache), per_family, resolution))
                       for a, s in jobs]
            for job in pending:
                records.append(job.get())
                r = records[-1]
                log(f"ablate: {r['arm']} seed {r['seed']}: {r['psnr_distant']:.2f} dB")
            pool.close()
        except BaseException:
            pool.terminate()
            raise
        finally:
            pool.join()
    return {"steps": settings.steps, "seeds": list(settings.seeds), "arms": list(settings.arms),
            "per_family": per_family, "resolution": resolution, "records": records,
            **summarise(records, sign_bar=sign_bar, failure_below=failure_below)}


def paired_effect(a: Sequence[float], b: Sequence[float], sign_bar: float = SIGN_BAR_SE) -> dict[str, Any]:
    """Mean ± sample std of the per-seed differences a − b, its standard error and the sign, called
    when |mean| ≥ ``sign_bar`` standard errors; beside them (deciding nothing) the median
    difference, the number of seeds where ``a`` is ahead, ``z`` = mean / standard error, whether the
    plain two-standard-error rule would call it, and the two-sided Wilcoxon signed-rank p-value,
    which a few large differences (failed runs) cannot carry as they can the mean."""
    d = np.asarray(a, float) - np.asarray(b, float)
    n = d.size
    std = float(d.std(ddof=1)) if n > 1 else math.nan
    se = std / math.sqrt(n) if n > 1 else math.nan
    mean = float(d.mean())
    z = mean / se if n > 1 and se > 0 else math.nan
    if n < 2 or not math.isfinite(se):
        sign = "undetermined (one seed)"
    elif abs(mean) >= sign_bar * se:
        sign = "positive" if mean > 0 else "negative"
    else:
        sign = f"not resolved (mean within {sign_bar:g} standard errors of zero)"
    return {"mean": mean, "std": std, "se": se, "n": n, "sign": sign, "sign_bar": float(sign_bar),
            "z": float(z), "passes_two_se": bool(n > 1 and abs(mean) >= 2.0 * se),
            "median": float(np.median(d)), "ahead": int((d > 0).sum()), "wilcoxon_p": wilcoxon_p(d)}


def stratified_effect(strata: dict[str, tuple[float, Sequence[float]]], sign_bar: float = SIGN_BAR_SE,
                      min_per_stratum: int = 3) -> dict[str, Any]:
    """Stratified mean of per-seed paired differences (dB): d̂ = Σ_h W_h·mean_h over strata h with
    population shares W_h (summing to 1), standard error √(Σ_h W_h²·s_h²/n_h) with each stratum's
    sample std s_h over its n_h seeds; the sign is called at ``sign_bar`` standard errors, and only
    once every stratum has ``min_per_stratum`` seeds. Beside it, deciding nothing: the
    Welch–Satterthwaite degrees of freedom ν = (Σ v_h)² / Σ v_h²/(n_h − 1), v_h = W_h²·s_h²/n_h, and
    the t-based 95 % interval d̂ ± t₀.₉₇₅(ν)·SE (a stratum of three seeds knows its own spread
    poorly, which the plain two-standard-error rule ignores)."""
    from scipy.stats import t as student_t

    weights = {h: float(w) for h, (w, _) in strata.items()}
    if abs(sum(weights.values()) - 1.0) > 1e-9 or min(weights.values()) <= 0:
        raise ValueError(f"stratum shares must be positive and sum to 1, got {weights}")
    rows = {}
    for h, (w, diffs) in strata.items():
        d = np.asarray(diffs, float)
        n = d.size
        rows[h] = {"share": float(w), "n": n, "mean": float(d.mean()) if n else math.nan,
                   "std": float(d.std(ddof=1)) if n > 1 else math.nan}
    if any(r["n"] < max(2, min_per_stratum) for r in rows.values()):
        short = ", ".join(f"{h} {r['n']}" for h, r in rows.items())
        return {"strata": rows, "estimate": math.nan, "se": math.nan, "df": math.nan,
                "ci95": [math.nan, math.nan], "sign_bar": float(sign_bar),
                "sign": f"not computed (each stratum needs {min_per_stratum} seeds; has {short})"}
    v = {h: r["share"] ** 2 * r["std"] ** 2 / r["n"] for h, r in rows.items()}
    est = sum(r["share"] * r["mean"] for r in rows.values())
    se = math.sqrt(sum(v.values()))
    df = sum(v.values()) ** 2 / sum(v[h] ** 2 / (rows[h]["n"] - 1) for h in rows) if se > 0 else math.inf
    half = float(student_t.ppf(0.975, df)) * se if math.isfinite(df) else 1.959963984540054 * se
    if se > 0 and abs(est) >= sign_bar * se:
        sign = "positive" if est > 0 else "negative"
    else:
        sign = f"not resolved (estimate within {sign_bar:g} standard errors of zero)"
    return {"strata": rows, "estimate": est, "se": se, "z": est / se if se > 0 else math.inf, "df": df,
            "ci95": [est - half, est + half], "sign_bar": float(sign_bar), "sign": sign}


def wilcoxon_p(differences: Sequence[float]) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired differences (scipy: exact for small samples
    without ties or zeros, the normal approximation otherwise); NaN under two non-zero differences."""
    d = np.asarray(differences, float)
    if np.count_nonzero(d) < 2:
        return math.nan
    from scipy.stats import wilcoxon

    return float(wilcoxon(d, alternative="two-sided").pvalue)


def summarise(records: Sequence[dict[str, Any]], sign_bar: float = SIGN_BAR_SE,
              failure_below: float | None = None) -> dict[str, Any]:
    """Per-arm mean ± std over seeds (and, with ``failure_below`` in dB, the seeds that scored under
    it) and the paired effects of :data:`EFFECTS`, signs called at ``sign_bar`` standard errors."""
    by_arm: dict[str, dict[int, float]] = {}
    for r in records:
        by_arm.setdefault(r["arm"], {})[int(r["seed"])] = float(r["psnr_distant"])
    arms = {a: {"mean": float(np.mean(list(v.values()))),
                "std": float(np.std(list(v.values()), ddof=1)) if len(v) > 1 else math.nan,
                "per_seed": {str(k): v[k] for k in sorted(v)}} for a, v in by_arm.items()}
    if failure_below is not None:
        for a, v in by_arm.items():
            arms[a]["failures"] = {"below_db": float(failure_below),
                                   "seeds": [k for k in sorted(v) if v[k] < failure_below]}
    effects = {}
    for label, with_it, without in EFFECTS:
        if with_it in by_arm and without in by_arm:
            common = sorted(set(by_arm[with_it]) & set(by_arm[without]))
            if common:
                effects[label] = paired_effect([by_arm[with_it][s] for s in common],
                                               [by_arm[without][s] for s in common], sign_bar)
    return {"by_arm": arms, "effects": effects}


#: Two scores of one (arm, seed) agree when they differ by no more than this (dB): the rounding
#: of a two-decimal table, the form in which earlier studies were published.
SAME_SCORE_DB = 0.005


def load_records(path: str | Path, steps: int) -> list[dict[str, Any]]:
    """The records of an earlier study (an ``ablate --json`` file, or any JSON object with
    ``steps`` and ``records`` of ``arm``, ``seed``, ``psnr_distant``), refused unless it was trained
    at ``steps`` steps with known arms: pooling different budgets would mix two experiments."""
    import json

    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SpecGenError(f"{path}: not a readable JSON file of ablation records ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("records"), list):
        raise SpecGenError(f"{path}: has no list of 'records' (an `ablate --json` output is expected)")
    if data.get("steps") != steps:
        raise SpecGenError(f"{path}: its arms trained {data.get('steps')} steps, this study {steps}; "
                           "only studies of one budget can be pooled")
    records = []
    for r in data["records"]:
        try:
            rec = {**r, "arm": str(r["arm"]), "seed": int(r["seed"]), "psnr_distant": float(r["psnr_distant"])}
        except (TypeError, KeyError, ValueError):
            raise SpecGenError(f"{path}: a record lacks an arm, a seed or a psnr_distant: {r!r}") from None
        if rec["arm"] not in ARMS_BY_NAME or not math.isfinite(rec["psnr_distant"]):
            raise SpecGenError(f"{path}: a record has an unknown arm or a non-finite score: {r!r}")
        records.append(rec)
    return records


def pool_records(new: Sequence[dict[str, Any]], earlier: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """This run's records with an earlier study's. Where both scored one (arm, seed) the two must
    agree to :data:`SAME_SCORE_DB` (training and scoring are deterministic, so a retrained arm is a
    check of the earlier figure) and this run's is kept; a disagreement is an error."""
    pooled = {(r["arm"], int(r["seed"])): r for r in earlier}
    for r in new:
        key = (r["arm"], int(r["seed"]))
        old = pooled.get(key)
        if old is not None and abs(float(old["psnr_distant"]) - float(r["psnr_distant"])) > SAME_SCORE_DB:
            raise SpecGenError(f"{key[0]} seed {key[1]} scores {r['psnr_distant']:.3f} dB now but "
                               f"{float(old['psnr_distant']):.3f} dB in the earlier records; they cannot be pooled")
        pooled[key] = r
    return [pooled[k] for k in sorted(pooled, key=lambda k: (k[1], k[0]))]


def format_markdown(study: dict[str, Any]) -> str:
    """The study as markdown: a table of arms (per seed, mean ± std), each arm's failed runs where a
    threshold was given, and a table of effects (paired)."""
    seeds = study["seeds"]
    lines = ["| arm | " + " | ".join(f"seed {s}" for s in seeds) + " | mean ± std |",
             "| --- | " + " | ".join("---:" for _ in seeds) + " | ---: |"]
    for arm, s in study["by_arm"].items():
        cells = [f"{s['per_seed'][str(k)]:.2f}" if str(k) in s["per_seed"] else "—" for k in seeds]
        lines.append(f"| {arm} | " + " | ".join(cells) + f" | {_mean_pm_std(s['mean'], s['std'])} |")
    failed = [(arm, s["failures"], len(s["per_seed"])) for arm, s in study["by_arm"].items() if "failures" in s]
    if failed:
        lines += ["", f"Failed runs (under {failed[0][1]['below_db']:g} dB): " + "; ".join(
            f"{arm} {len(f['seeds'])} of {n}" + (f" (seeds {', '.join(map(str, f['seeds']))})" if f["seeds"] else "")
            for arm, f, n in failed) + "."]
    lines += ["", "| effect (paired by seed) | mean ± std (dB) | standard error | sign | median (dB) | ahead in "
                  "| mean / SE | Wilcoxon p |",
              "| --- | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
    for label, e in study["effects"].items():
        z, p = e["z"], e["wilcoxon_p"]
        lines.append(f"| {label} | {_mean_pm_std(e['mean'], e['std'], signed=True)} | {_number(e['se'], '.2f')} "
                     f"| {e['sign']} | {e['median']:+.2f} | {e['ahead']} of {e['n']} "
                     f"| {_number(z, '+.2f')} | {_number(p, '.3f')} |")
    return "\n".join(lines) + "\n"


def _number(x: float, spec: str) -> str:
    """``x`` formatted, or a dash where it is undefined (a std or standard error of one seed)."""
    return format(x, spec) if math.isfinite(x) else "—"


def _mean_pm_std(mean: float, std: float, signed: bool = False) -> str:
    """``mean ± std``, or the mean alone where one seed leaves the std undefined."""
    m = format(mean, "+.2f" if signed else ".2f")
    return f"{m} ± {std:.2f}" if math.isfinite(std) else m


def seed_ranges(seeds: Sequence[int]) -> str:
    """Seeds written compactly, consecutive runs as ranges: ``[5, 6, 7, 9]`` → ``"5–7, 9"``."""
    runs: list[list[int]] = []
    for s in sorted(set(seeds)):
        if runs and s == runs[-1][-1] + 1:
            runs[-1].append(s)
        else:
            runs.append([s])
    return ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}–{r[-1]}" for r in runs)


def plot_study(study: dict[str, Any], path: Path) -> Path:
    """Dot plot: each arm's per-seed PSNR (dots) and mean ± std (bar), held-out split, distant lights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    arms = list(study["by_arm"])
    seeds = sorted({int(k) for arm in arms for k in study["by_arm"][arm]["per_seed"]})
    offsets = dict(zip(seeds, np.linspace(-0.12, 0.12, len(seeds))))
    fig, ax = plt.subplots(figsize=(2.4 + 1.4 * len(arms), 3.6), dpi=110)
    for seed in seeds:  # one grey line per seed joins its arms: the effects are paired by seed
        scores = [(i + offsets[seed], study["by_arm"][arm]["per_seed"].get(str(seed))) for i, arm in enumerate(arms)]
        ax.plot(*zip(*[(x, y) for x, y in scores if y is not None]), color="0.75", lw=0.8, zorder=2)
    for i, arm in enumerate(arms):
        s = study["by_arm"][arm]
        keys = sorted(s["per_seed"], key=int)
        ax.scatter([i + offsets[int(k)] for k in keys], [s["per_seed"][k] for k in keys], s=22, color="C0",
                   zorder=3)
        ax.errorbar(i + 0.28, s["mean"], yerr=0 if not np.isfinite(s["std"]) else s["std"], fmt="s", color="k",
                    capsize=4, zorder=3)
    thresholds = {s["failures"]["below_db"] for s in study["by_arm"].values() if "failures" in s}
    for t in thresholds:  # the failure threshold the study counted runs under, if any
        ax.axhline(t, color="C3", ls="--", lw=0.8, zorder=1)
        ax.text(-0.48, t, f"failed: under {t:g} dB", color="C3", fontsize=7, ha="left", va="bottom")
    ax.set_xticks(range(len(arms)), arms)
    ax.set_xlim(-0.5, len(arms) - 0.3)
    ax.set_ylabel("spectral PSNR (dB), held-out split")
    title = (f"{study['steps']} steps from scratch, {len(study['seeds'])} seeds ({seed_ranges(study['seeds'])}): "
             "dots per seed (grey lines join a seed's arms), ■ mean ± std")
    ax.set_title(textwrap.fill(title, 48), fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
