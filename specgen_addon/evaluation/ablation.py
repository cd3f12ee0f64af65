"""Equal-budget training arms for the ablations (paper §4.4, Tables 3 and 4).

Four arms of the same network (the shipped model's :class:`~specgen_addon.model.Config`, fusion
swapped) trained by the project's own training loop (:func:`specgen_addon.train.loop.train`):

============================  ========  ===========================================
arm                           fusion    data
============================  ========  ===========================================
``spectral-aff``              AFF       corpus spectral materials only
``joint-aff``                 AFF       + RGB materials (corpus RGB versions, real RGL RGB files)
``spectral-hadamard``         Hadamard  corpus spectral materials only
``joint-hadamard``            Hadamard  + RGB materials
============================  ========  ===========================================

Every arm gets the same budget: the same number of steps and the same seeds, and therefore the
same spectral batches (a step's batches are a pure function of ``(seed, step)`` and the spectral
draw comes first); joint arms add an RGB batch to each step. Each arm is trained once per seed
(:data:`SEEDS`) and the tables report the mean over seeds, with the per-seed values beside it. A budget given in minutes is converted
once to a step count from a short timing of the joint AFF step and the count is cached, so reruns
and resumes train exactly the same steps (wall-clock budgets would not be deterministic).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from specgen_addon.common.cache import read_json, write_json
from specgen_addon.common.cache import cache_root
from specgen_addon.evaluation import report
from specgen_addon.model import Config


@dataclass(frozen=True)
class Arm:
    name: str
    label: str
    fusion: str
    joint: bool


ARMS = (
    Arm("spectral-aff", "Spectral only (AFF)", "aff", False),
    Arm("joint-aff", "Joint RGB + spectral (AFF)", "aff", True),
    Arm("spectral-hadamard", "Spectral only (Hadamard)", "hadamard", False),
    Arm("joint-hadamard", "Joint RGB + spectral (Hadamard)", "hadamard", True),
)
ARMS_BY_NAME = {a.name: a for a in ARMS}
#: Default step budget of every arm (a tenth of the shipped model's 5000 steps).
DEFAULT_STEPS = 500
SMOKE_STEPS = 3
#: The smoke run trains on a tiny prefix of the corpus with one input lighting per material.
SMOKE_TRAIN = {"corpus_size": 12, "input_variants": 1, "val_every": 10 ** 9, "val_materials": 2}
#: Seeds every arm is trained with (the smoke run uses the first only).
SEEDS = (0, 1)
#: Fields added to the model / training configs after arms were first cached. At their defaults
#: they leave a run unchanged, so :meth:`AblationSettings.key` leaves them out and the arms cached
#: before they existed keep their keys (a documented table's command then trains nothing). A field
#: added later belongs here too: tests/evaluation/test_ablation_study.py checks the recorded keys and fails until it is.
KEY_NEUTRAL_AT_DEFAULT = {"m": ("encoder_negative_slope",),
                          "t": ("fresh_encoder", "frozen", "family_draw",
                                "recolour_p", "material_balance", "balance_floor", "real_materials_per_step",
                                "real_weight", "real_rgb_dir", "real_exclude", "real_exposure_jitter",
                                "real_white_balance_jitter", "corpus_train_limit")}


@dataclass
class AblationSettings:
    """Budget and configuration shared by every arm."""

    steps: int
    seeds: tuple[int, ...] = SEEDS
    arms: tuple[str, ...] = tuple(a.name for a in ARMS)
    model: dict[str, Any] = field(default_factory=dict)        # Config fields (fusion set per arm)
    train: dict[str, Any] = field(default_factory=dict)        # TrainConfig fields shared by all arms
    budget_note: str = ""

    def configs(self, arm: Arm, seed: int):
        """(model Config, TrainConfig) of ``arm`` trained with ``seed``."""
        from specgen_addon.train.loop import TrainConfig

        mcfg = Config.from_dict({**self.model, "fusion": arm.fusion})
        t = {**self.train, "seed": seed, "steps": self.steps,
             "lr_decay_every": max(1, self.steps // 4), "max_minutes": None}
        if not arm.joint:
            t.update(rgb_materials_per_step=0, use_shared_rgl=False)
        return mcfg, TrainConfig.from_dict(t)

    def key(self, arm: Arm, seed: int) -> str:
        import hashlib
        import json

        mcfg, tcfg = self.configs(arm, seed)
        t = dataclasses.asdict(tcfg)
        t.pop("device")  # where an arm trains is not part of what it is (and keeps older keys valid)
        parts = {"m": mcfg.to_dict(), "t": t}
        # the defaults written the same way as the key's parts, so a value compares like with like
        defaults = {"m": type(mcfg)().to_dict(), "t": dataclasses.asdict(type(tcfg)())}
        for part, names in KEY_NEUTRAL_AT_DEFAULT.items():
            for name in names:
                if name in parts[part] and parts[part][name] == defaults[part][name]:
                    del parts[part][name]
        blob = json.dumps(parts, sort_keys=True, default=str)
        return f"{arm.name}-{hashlib.sha1(blob.encode()).hexdigest()[:10]}"

    def describe_markdown(self, results: dict[str, "ArmResult"]) -> str:
        rows = [[r.label, r.fusion.upper() if r.fusion == "aff" else "Hadamard",
                 "corpus spectral + RGB" if r.joint else "corpus spectral", str(r.steps), str(r.seed),
                 f"{r.wall_seconds / 60:.1f} min"] for r in results.values()]
        seeds = ", ".join(str(x) for x in self.seeds)
        text = (f"Ablation arms: same network as the shipped model (fusion swapped), each trained for "
                f"**{self.steps} steps** with each of the seeds {seeds} {self.budget_note}; learning rate halved "
                f"every {max(1, self.steps // 4)} steps (four times per run, as the paper's schedule). "
                "Wall times are as measured (the machine was shared, so they vary; the step budget does not).\n\n")
        return text + report.md_table(["Arm", "Fusion", "Training data", "Steps", "Seed", "Wall time"], rows,
                                      "lllrrr")


@dataclass
class ArmResult:
    name: str
    key: str
    label: str
    fusion: str
    joint: bool
    weights: Path
    steps: int
    wall_seconds: float
    seed: int


REPO_ROOT = Path(__file__).resolve().parents[2]
#: The shipped model's training configuration (``python -m specgen_addon train`` default).
DEFAULT_CONFIG = REPO_ROOT / "configs" / "default.json"


def _default_configs() -> tuple[dict[str, Any], dict[str, Any]]:
    """(model, train) dicts of the shipped model's config file (Config/TrainConfig defaults without it).

    Ablation arms train from scratch: the config's ``init_weights`` (a warm start from the shipped
    weights) is dropped, so every arm starts equal and arms of another architecture can train."""
    from specgen_addon.train.loop import TrainConfig, load_config

    if DEFAULT_CONFIG.is_file():
        mcfg, tcfg = load_config(DEFAULT_CONFIG)
    else:
        mcfg, tcfg = Config(), TrainConfig()
    return mcfg.to_dict(), dataclasses.asdict(dataclasses.replace(tcfg, init_weights=None))


def ablation_settings(smoke: bool = False, steps: int | None = None, budget_minutes: float | None = None,
                      cache_dir: Path | None = None, log: Callable[[str], None] = print) -> AblationSettings:
    """Settings of the ablation: an explicit step count, the smoke budget, minutes → steps, or
    :data:`DEFAULT_STEPS`."""
    model, train_d = _default_configs()
    if smoke:
        train_d = {**train_d, **SMOKE_TRAIN}
    if steps is not None:
        return AblationSettings(steps=int(steps), model=model, train=train_d, budget_note="(step budget given)")
    if smoke:
        return AblationSettings(steps=SMOKE_STEPS, seeds=SEEDS[:1], model=model, train=train_d,
                                budget_note="(smoke budget)")
    if budget_minutes is None:
        return AblationSettings(steps=DEFAULT_STEPS, model=model, train=train_d,
                                budget_note=f"(the default budget; the shipped model's config trains "
                                            f"{train_d.get('steps')} steps)")
    minutes = float(budget_minutes)
    probe = AblationSettings(steps=1, model=model, train=train_d)
    timing_path = None if cache_dir is None else Path(cache_dir) / f"step_timing_{minutes:g}min.json"
    cached = read_json(timing_path) if timing_path is not None else None
    if cached is None:
        sec = time_steps(probe, log=log)
        cached = {"seconds_per_step": sec, "steps": max(10, int(minutes * 60.0 / sec))}
        if timing_path is not None:
            write_json(timing_path, cached)
    return AblationSettings(steps=int(cached["steps"]), model=model, train=train_d,
                            budget_note=f"(≈ {minutes:g} min each: {cached['seconds_per_step']:.2f} s per joint "
                                        "AFF step measured once, then fixed as a step count)")


def _material_sets(tcfg, mcfg, cache_dir: Path, log: Callable[[str], None]):
    from specgen_addon.train import build_material_sets

    return build_material_sets(mcfg, tcfg, cache_dir=cache_dir, log=log)


def time_steps(settings: AblationSettings, n: int = 12, log: Callable[[str], None] = print) -> float:
    """Seconds per training step of the joint AFF arm (median-free mean of ``n`` steps after warm-up)."""
    import tempfile

    from specgen_addon.train.loop import train

    arm = ARMS_BY_NAME["joint-aff"]
    probe = dataclasses.replace(settings, steps=n + 2)
    mcfg, tcfg = probe.configs(arm, probe.seeds[0])
    tcfg = dataclasses.replace(tcfg, val_every=10 ** 9, checkpoint_every=10 ** 9)
    spectral, rgb, val = _material_sets(tcfg, mcfg, _data_cache(), log)
    stamps: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        train(mcfg, tcfg, spectral, rgb, val, tmp, show_progress=False,
              on_step=lambda step, rec: stamps.append(time.perf_counter()))
    return (stamps[-1] - stamps[1]) / (len(stamps) - 2)


def _data_cache() -> Path:
    """The cache of training input renders shared with the training runs (nothing rendered twice)."""
    return cache_root() / "train-data"


#: TrainConfig fields a caller may change for one run of an arm: where and how fast it trains, and
#: when this run stops (a stopped arm resumes from its checkpoint). None of them changes the batches
#: or the schedule, so an arm keeps its key; a GPU repeats a CPU run to float rounding only.
RUN_ONLY_FIELDS = ("device", "data_workers", "render_workers", "max_minutes")


def train_arms(settings: AblationSettings, cache_dir: Path, progress: bool = True,
               log: Callable[[str], None] = print,
               run_overrides: dict[str, Any] | None = None) -> dict[str, ArmResult]:
    """Train (or resume, or load) every arm with every seed; results by ``"<arm>/seed<k>"``.

    ``run_overrides`` sets :data:`RUN_ONLY_FIELDS` for this run (e.g. ``{"device": "cuda"}``). An arm
    that stops before its budget (``max_minutes``) is left without ``arm.json``, so it is neither
    scored nor reported until a later run finishes it; it is then missing from the result."""
    from specgen_addon.train.loop import train

    overrides = dict(run_overrides or {})
    unknown = sorted(set(overrides) - set(RUN_ONLY_FIELDS))
    if unknown:
        raise ValueError(f"run_overrides may only set {', '.join(RUN_ONLY_FIELDS)}, not {', '.join(unknown)}")
    out: dict[str, ArmResult] = {}
    for seed in settings.seeds:
        for name in settings.arms:
            arm = ARMS_BY_NAME[name]
            key = settings.key(arm, seed)
            arm_dir = Path(cache_dir) / key
            info_path = arm_dir / "arm.json"
            info = read_json(info_path)
            if info is None or not (arm_dir / "specgen.pt").is_file():
                mcfg, tcfg = settings.configs(arm, seed)
                tcfg = dataclasses.replace(tcfg, **overrides)
                log(f"ablation: training {arm.label} for {settings.steps} steps (seed {seed})")
                spectral, rgb, val = _material_sets(tcfg, mcfg, _data_cache(), log)
                res = train(mcfg, tcfg, spectral, rgb, val, arm_dir, resume=True, show_progress=progress,
                            meta={"ablation_arm": arm.name})
                if res.stopped_early:
                    log(f"ablation: {arm.label} (seed {seed}) stopped at step {res.steps} of {settings.steps}")
                    continue
                info = {"steps": res.steps, "wall_seconds": res.wall_seconds, "seed": seed}
                write_json(info_path, info)
            out[f"{name}/seed{seed}"] = ArmResult(name, key, arm.label, arm.fusion, arm.joint,
                                                  arm_dir / "specgen.pt", int(info["steps"]),
                                                  float(info["wall_seconds"]), int(info["seed"]))
    return out


def save_arms(path: Path, settings: AblationSettings, arms: dict[str, ArmResult]) -> None:
    """Record which trained arms a run scored (read back by :func:`load_arms` for ``--report-only``)."""
    write_json(path, {"steps": settings.steps, "seeds": list(settings.seeds), "budget_note": settings.budget_note,
                      "arms": {k: {**dataclasses.asdict(a), "weights": str(a.weights)} for k, a in arms.items()}})


def load_arms(path: Path) -> tuple[AblationSettings | None, dict[str, ArmResult]]:
    """The ablation settings and arms recorded by :func:`save_arms` (none when absent)."""
    data = read_json(path)
    if data is None:
        return None, {}
    arms = {k: ArmResult(**{**a, "weights": Path(a["weights"])}) for k, a in data["arms"].items()}
    return AblationSettings(steps=data["steps"], seeds=tuple(data["seeds"]), budget_note=data["budget_note"]), arms
