"""Joint RGB + spectral training of SpecGen (paper §3.3, §4.2) on the CPU (or a GPU: ``device``).

Each step draws a few spectral materials and a few RGB materials (seeded by ``(seed, step)``, so a
resumed run continues exactly as an uninterrupted one), renders nothing (input images are
pre-rendered and cached) and minimises

``L = L_spec + w_rgb · L_RGB + α · L_TV``

with ``L_spec`` the MSE of μ-law reflectance at (θh, θd, φd, λ) points, ``L_RGB`` the MSE against
the μ-law of the RGB channel mean using λ-averaged spectral features, and ``L_TV`` the planes'
total variation (paper: α = 2). Adam (β = 0.9, 0.999) with a step-decayed learning rate, as the
paper halves it every four epochs. Bit-for-bit deterministic on CPU for a fixed seed and thread
count (on a GPU: to float rounding).
"""

from __future__ import annotations

import collections
import contextlib
import csv
import dataclasses
import functools
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from specgen_addon.train.config_schema import MODEL_BOUNDS, TRAIN_BOUNDS, type_error, read_config_dict, validate_section
from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.model import Config, SpecGen, count_parameters, save_weights
from specgen_addon.spectral.spectra import wavelength_grid
from specgen_addon.train import distributed as ddp
from specgen_addon.train.data import Batch, TrainingMaterial, make_batch
from specgen_addon.train.lighting_mix import mix_lighting
from specgen_addon.train.losses import balanced_mse, foreshortening, masked_mse, rendered_scale_loss
from specgen_addon.train.prefetch import step_batches
from specgen_addon.train.real_rgb import real_loss, real_source
from specgen_addon.common.cache import cache_root
from specgen_addon.corpus.generate import check_mix, material_family
from specgen_addon.model import load_weights
from specgen_addon.model.config import retire_keys
from specgen_addon.model.grow import can_grow, grow_state_dict

#: Band grid (nm) the spectral targets are evaluated on: 10 nm steps over the visible range.
TARGET_WAVELENGTHS_NM = wavelength_grid(380.0, 780.0, 41)
#: The network's top-level modules, as ``frozen`` names them.
MODULES = ("encoder", "generator", "fusion", "mapping")
#: Training config keys of an experiment earlier versions carried (renewing dead units at a warm
#: start), with the value that meant "off" (None: any value); the record is in lab/notebook.
RETIRED_KEYS = {"recycle_dormant": [], "recycle_mode": None}


@dataclass
class TrainConfig:
    """Training knobs (the model's sizes live in :class:`~specgen_addon.model.Config`)."""

    seed: int = 0
    steps: int = 6000
    max_minutes: float | None = None
    lr: float = 2e-3
    lr_decay_every: int = 1500
    lr_decay: float = 0.5
    spectral_materials_per_step: int = 6
    rgb_materials_per_step: int = 2
    angles_per_material: int = 512
    wavelengths_per_angle: int = 8
    tv_weight: float = 2.0
    rgb_weight: float = 1.0
    #: Weight of the rendered-scale term (:func:`rendered_scale_loss`) added to each group's
    #: μ-law MSE (0: off, the paper's loss).
    linear_loss_weight: float = 0.0
    #: How a group's μ-law MSE is pooled over its materials: "mean" (the paper: the MSE of all
    #: points, so the worst-fitted materials steer the gradient) or "log" (:func:`balanced_mse`: the
    #: gradient of the mean over materials of log(MSE_m + floor·M̄), scaled by the batch's M̄: each
    #: material weighed as the figure it is scored by, a mean over materials of PSNR in dB, does).
    material_balance: str = "mean"
    #: With ``material_balance`` "log": the floor under each material's MSE, as a fraction of the
    #: batch's mean MSE (a material fitted far better than the rest gets at most 1/floor times the
    #: plain weight).
    balance_floor: float = 0.1
    #: Largest random shift (network pixels, each axis) and relative scale change of every training
    #: input (0: off), as a real photo's crop leaves the sphere a fraction of a pixel off centre and
    #: a fraction of a pixel too wide (:mod:`.augment`).
    input_jitter_px: float = 0.0
    input_scale_jitter: float = 0.0
    #: Fraction of training inputs handed over as the pipeline crops a photo whose sphere lies off
    #: the pixel grid, with the sphere finder's error in pixels (:func:`.augment.offgrid_photo_crop`;
    #: 0: off).
    input_offgrid_fraction: float = 0.0
    input_finder_error_px: float = 0.07
    corpus_size: int = 200
    corpus_seed: int = 0
    input_variants: int = 4
    png_augment: bool = True
    canonical_fraction: float = 0.75
    use_shared_rgl: bool = False
    brdf_dirs: list[str] = field(default_factory=list)
    #: Real RGB measurements drawn at every step (0: off), each supervising the RGB side in colour
    #: and grey (:mod:`.real_rgb`), weighed by ``real_weight``; taken from ``real_rgb_dir`` (None:
    #: ../shared/data/rgl) less the stems in ``real_exclude`` (a cross-validation fold's held-out
    #: files), augmented by exposure (σ in stops) and white balance (σ of each channel's log gain).
    real_materials_per_step: int = 0
    real_weight: float = 1.0
    real_rgb_dir: str | None = None
    real_exclude: list[str] = field(default_factory=list)
    real_exposure_jitter: float = 0.0
    real_white_balance_jitter: float = 0.0
    #: Train on at most this many of the corpus' training materials, spread evenly over its order
    #: (0: all): a short fine-tune renders only the inputs it uses; the split stays the corpus'.
    corpus_train_limit: int = 0
    checkpoint_every: int = 250
    val_every: int = 250
    val_materials: int = 8
    threads: int = 2
    #: Family mix of the corpus (family → weight); None: the classic recipe only.
    families: dict[str, float] | None = None
    #: Chance of each family at every step's draw (family → weight; normalised): each material is
    #: drawn with its family's weight shared among the family's materials, so the corpus (and with
    #: it the test split) keeps the ``families`` mix while the steps see another. None: every
    #: training material is equally likely (the earlier runs' draws, bit for bit).
    family_draw: dict[str, float] | None = None
    #: Chance that a drawn spectral training material is recoloured for the step: its first
    #: reflectance the BRDF is affine in is replaced by a random spectrum of the training materials'
    #: own, and its canonical input recombined exactly from two cached per-band renders
    #: (:mod:`.recolour`): new combinations of familiar parts at every step. Needs ``lighting="mix"``.
    #: 0 (default): off, the earlier runs' draws bit for bit.
    recolour_p: float = 0.0
    #: "variants": cached renders under ``input_variants`` fixed lightings; "mix": lighting drawn
    #: per step from cached components (:mod:`.lighting_mix`).
    lighting: str = "variants"
    #: Start from these weights (same model config) instead of a random initialisation.
    init_weights: str | None = None
    #: Start the encoder at a random initialisation and take only the decoder, fusion and mapping
    #: from ``init_weights`` (the encoder's config may then differ: :func:`.grow.can_grow`).
    fresh_encoder: bool = False
    #: Top-level modules that do not train ("encoder", "generator", "fusion", "mapping"; empty:
    #: all train): a new encoder can learn for a fixed, trained decoder.
    frozen: list[str] = field(default_factory=list)
    #: Processes rendering missing input images before training.
    render_workers: int = 2
    #: Processes making step batches ahead of the network (:mod:`.prefetch`; the same run, bit for
    #: bit): worth it on a GPU, where numpy is the bound; 0 (default) makes each when needed.
    data_workers: int = 0
    #: Where the network trains: "cpu", "cuda" (one GPU per rank; DDP then uses nccl) or "auto"
    #: (cuda when available). Targets and inputs are made on the CPU either way.
    device: str = "cpu"
    #: Decay of an exponential moving average of the weights (0: off). When on, validation scores
    #: and ``specgen.pt`` holds the average (torch.optim.swa_utils.AveragedModel), which smooths
    #: the step-to-step noise of a small batch; the checkpoint keeps both.
    ema_decay: float = 0.0
    #: Every this many steps from ``snapshot_from`` on, the weights ``specgen.pt`` would hold then
    #: are saved as ``snapshots/stepNNNNNN.pt`` (0: off), for averaging afterwards
    #: (``average-weights``, :mod:`specgen_addon.model.average`).
    snapshot_every: int = 0
    snapshot_from: int = 0

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainConfig":
        names = {f.name for f in dataclasses.fields(cls)}
        d = retire_keys(d, RETIRED_KEYS, "training config")
        unknown = set(d) - names
        if unknown:
            raise SpecGenError(f"unknown training config keys: {sorted(unknown)}")
        try:
            cfg = cls(**d)
        except TypeError as exc:
            raise SpecGenError(f"bad training config ({exc})") from None
        cfg.validate()
        return cfg

    def validate(self) -> "TrainConfig":
        """Raise one SpecGenError naming the first bad value (sizes, seeds, families, modes)."""
        def is_int(v: Any) -> bool:
            return isinstance(v, int) and not isinstance(v, bool)

        for key, lo in (("seed", 0), ("corpus_seed", 0), ("steps", 1), ("corpus_size", 1),
                        ("spectral_materials_per_step", 0), ("rgb_materials_per_step", 0),
                        ("angles_per_material", 1), ("wavelengths_per_angle", 1), ("input_variants", 1),
                        ("lr_decay_every", 1), ("checkpoint_every", 1), ("val_every", 1),
                        ("val_materials", 0), ("threads", 1), ("render_workers", 1), ("data_workers", 0),
                        ("snapshot_every", 0), ("snapshot_from", 0), ("real_materials_per_step", 0),
                        ("corpus_train_limit", 0)):
            v = getattr(self, key)
            if not is_int(v) or v < lo:
                raise SpecGenError(f"training config: {key} must be an integer ≥ {lo}, got {v!r}")
        for key in ("lr", "lr_decay", "tv_weight", "rgb_weight", "linear_loss_weight", "balance_floor",
                    "input_jitter_px", "real_weight", "real_exposure_jitter", "real_white_balance_jitter",
                    "input_scale_jitter", "input_finder_error_px", "canonical_fraction"):
            v = getattr(self, key)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or v < 0:
                raise SpecGenError(f"training config: {key} must be a finite number ≥ 0, got {v!r}")
        if not (isinstance(self.ema_decay, (int, float)) and not isinstance(self.ema_decay, bool)
                and 0.0 <= self.ema_decay < 1.0):
            raise SpecGenError(f"training config: ema_decay must be a number in [0, 1), got {self.ema_decay!r}")
        if self.lr <= 0 or self.canonical_fraction > 1:
            raise SpecGenError("training config: lr must be > 0 and canonical_fraction ≤ 1")
        for key in ("input_offgrid_fraction", "recolour_p"):
            f = getattr(self, key)
            if not isinstance(f, (int, float)) or isinstance(f, bool) or not 0.0 <= f <= 1.0:
                raise SpecGenError(f"training config: {key} must be a number in [0, 1], got {f!r}")
        if self.recolour_p > 0 and self.lighting != "mix":
            raise SpecGenError("training config: recolour_p needs lighting \"mix\" (it recombines the "
                               "canonical input from per-band renders)")
        f = self.input_offgrid_fraction
        if not isinstance(f, (int, float)) or isinstance(f, bool) or not 0.0 <= f <= 1.0:
            raise SpecGenError(f"training config: input_offgrid_fraction must be a number in [0, 1], got {f!r}")
        if self.max_minutes is not None and not (isinstance(self.max_minutes, (int, float))
                                                 and self.max_minutes > 0):
            raise SpecGenError(f"training config: max_minutes must be > 0, got {self.max_minutes!r}")
        if self.device not in ("cpu", "cuda", "auto"):
            raise SpecGenError(f"training config: device must be 'cpu', 'cuda' or 'auto', got {self.device!r}")
        if self.material_balance not in ("mean", "log"):
            raise SpecGenError(f"training config: material_balance must be 'mean' or 'log', "
                               f"got {self.material_balance!r}")
        if self.material_balance == "log" and not self.balance_floor > 0:
            raise SpecGenError("training config: balance_floor must be > 0 with material_balance \"log\"")
        if self.lighting not in ("variants", "mix"):
            raise SpecGenError(f"training config: lighting must be 'variants' or 'mix', got {self.lighting!r}")
        if self.spectral_materials_per_step + self.rgb_materials_per_step == 0:
            raise SpecGenError("training config: no materials per step")
        if self.families is not None:
            check_mix(self.families)
        if self.family_draw is not None:
            check_mix(self.family_draw)
            if self.families is not None and not set(self.family_draw) & set(self.families):
                raise SpecGenError("training config: family_draw names no family of the corpus mix "
                                   f"({', '.join(sorted(self.families))})")
        if self.init_weights is not None and not Path(self.init_weights).is_file():
            raise SpecGenError(f"training config: init_weights {self.init_weights}: file not found")
        if not isinstance(self.fresh_encoder, bool):
            raise SpecGenError(f"training config: fresh_encoder must be true or false, got {self.fresh_encoder!r}")
        if not isinstance(self.frozen, list) or any(m not in MODULES for m in self.frozen):
            raise SpecGenError(f"training config: frozen must list modules out of {', '.join(MODULES)}, "
                               f"got {self.frozen!r}")
        if (self.fresh_encoder or self.frozen) and self.init_weights is None:
            raise SpecGenError("training config: fresh_encoder and frozen need init_weights (the trained "
                               "modules they keep)")
        if self.fresh_encoder and "encoder" in self.frozen:
            raise SpecGenError("training config: a fresh encoder cannot be frozen (it would stay random)")
        return self


def load_config(path: str | Path) -> tuple[Config, TrainConfig]:
    """Read ``{"model": {...}, "train": {...}}`` from a JSON or TOML file, its ``extends`` bases
    merged in and a relative ``init_weights`` taken against the folder of the file that names it
    (:func:`~specgen_addon.train.config_schema.read_config_dict`)."""
    d = read_config_dict(path)
    unknown = set(d) - {"model", "train"}
    if unknown:
        raise SpecGenError(f"{path}: unknown sections {sorted(unknown)} (expected model, train)")
    train_d = dict(d.get("train", {}))
    mcfg, tcfg = Config.from_dict(d.get("model", {})), TrainConfig.from_dict(train_d)
    check_frozen(mcfg, tcfg)
    return mcfg, tcfg


def check_frozen(mcfg: Config, tcfg: TrainConfig) -> None:
    """Refuse a ``frozen`` list that names a module the model lacks or leaves nothing to train."""
    if set(MODULES) <= set(tcfg.frozen):
        raise SpecGenError("training config: frozen lists every module of this model, so nothing would train")


@dataclass
class MaterialSet:
    """Materials with their pre-rendered inputs ``(K, 3, S, S)`` (K lighting variants)."""

    materials: list[TrainingMaterial]
    images: list[np.ndarray]
    #: Chance of each material at a step's draw (None: uniform); :func:`family_draw_probabilities`.
    draw_p: np.ndarray | None = None
    #: Recolouring of members at each draw (``recolour_p`` > 0; :class:`.recolour.RecolourSource`).
    recolour: Any = None

    def __len__(self) -> int:
        return len(self.materials)


@dataclass
class TrainResult:
    weights: Path
    steps: int
    wall_seconds: float
    history: list[dict[str, float]]
    stopped_early: bool


def lr_at(tcfg: TrainConfig, step: int) -> float:
    """Step-decayed learning rate: ``lr · decay^(step // decay_every)``."""
    return tcfg.lr * tcfg.lr_decay ** (step // max(1, tcfg.lr_decay_every))


def family_draw_probabilities(materials: Sequence[TrainingMaterial], weights: dict[str, float]) -> np.ndarray:
    """Chance of each material at a step's draw: its family's share of ``weights`` (normalised)
    split evenly among that family's materials; a family without a weight is never drawn.

    SpecGenError when no material belongs to a weighted family.
    """
    share = check_mix(weights)
    families = [material_family(m.brdf) for m in materials]
    counts = collections.Counter(families)
    p = np.array([share.get(f, 0.0) / counts[f] for f in families], dtype=np.float64)
    if p.sum() <= 0:
        raise SpecGenError(f"training config: family_draw weights no family of the training set "
                           f"({', '.join(sorted(counts))})")
    return p / p.sum()


def _draw(rng: np.random.Generator, mset: MaterialSet, k: int, canonical_fraction: float,
          n_variants: int, lighting: str = "variants") -> tuple[list[TrainingMaterial], list[np.ndarray]]:
    """``k`` materials and one input image each: the canonical lighting with probability
    ``canonical_fraction`` (its linear or PNG version), else any of the material's images
    (``lighting="mix"``: a random environment or synthetic lighting, :func:`.lighting_mix.mix_lighting`).

    Coloured environment maps shift the sphere's colour, which a single image cannot tell apart
    from the material's own; mostly canonical inputs keep the colour → spectrum mapping sharp.
    """
    if mset.draw_p is None:
        idx = rng.choice(len(mset), size=min(k, len(mset)), replace=False)
    else:
        k = min(k, int(np.count_nonzero(mset.draw_p)))
        idx = rng.choice(len(mset), size=k, replace=False, p=mset.draw_p)
    mats, imgs = [], []
    for i in np.sort(idx):
        stack = mset.images[i]
        if mset.recolour is not None:
            drawn = mset.recolour.draw(rng, mset.materials[i], int(i), stack.shape[-1])
            if drawn is not None:
                mats.append(drawn[0])
                imgs.append(drawn[1])
                continue
        if lighting == "mix":
            mats.append(mset.materials[i])
            imgs.append(mix_lighting(stack, rng, canonical_p=canonical_fraction))
            continue
        canonical = np.arange(0, stack.shape[0], max(1, n_variants))   # variant 0 (and its PNG)
        if rng.random() < canonical_fraction:
            j = canonical[rng.integers(0, canonical.size)]
        else:
            j = rng.integers(0, stack.shape[0])
        mats.append(mset.materials[i])
        imgs.append(stack[j])
    return mats, imgs


def _tensors(b: Batch, device: torch.device | None = None) -> dict[str, torch.Tensor]:
    t = {k: torch.from_numpy(getattr(b, k)) for k in ("images", "theta_h", "theta_d", "phi_d", "target")}
    t["valid"] = torch.from_numpy(b.valid.astype(np.float32))
    t["wavelength_nm"] = None if b.wavelength_nm is None else torch.from_numpy(b.wavelength_nm)
    if device is not None and device.type != "cpu":
        t = {k: None if v is None else v.to(device, non_blocking=True) for k, v in t.items()}
    return t


def _device_of(model: torch.nn.Module) -> torch.device:
    return next(model.parameters()).device


def group_loss(model: SpecGen, b: Batch, linear_weight: float = 0.0, balance: str = "mean",
               balance_floor: float = 0.1) -> tuple[torch.Tensor, torch.Tensor]:
    """(data term, TV of the generated planes) for one batch group.

    The data term is the MSE in μ-law space (paper §3.3) — pooled over all points (``balance``
    "mean") or per material in log space (``"log"``, :func:`balanced_mse`) — plus
    ``linear_weight`` times :func:`rendered_scale_loss` when that is positive.
    """
    t = _tensors(b, _device_of(model))
    planes = model.planes(t["images"])
    pred = model.query(planes, t["theta_h"], t["theta_d"], t["phi_d"], t["wavelength_nm"])
    if balance == "log":
        data = balanced_mse(pred, t["target"], t["valid"], balance_floor)
    else:
        data = masked_mse(pred, t["target"], t["valid"])
    if linear_weight > 0:
        cos_w = foreshortening(t["theta_h"], t["theta_d"], t["phi_d"])
        data = data + linear_weight * rendered_scale_loss(pred, t["target"], t["valid"], cos_w,
                                                          model.cfg.mu)
    return data, model.tv_loss(planes)


def total_loss(tcfg: TrainConfig, g_spec: tuple[torch.Tensor, torch.Tensor] | None,
               g_rgb: tuple[torch.Tensor, torch.Tensor] | None,
               g_real: tuple[torch.Tensor, torch.Tensor] | None = None) -> tuple[torch.Tensor, dict[str, float]]:
    """``L = L_spec + w_rgb · L_RGB + w_real · L_real + α · L_TV`` from the groups' ``(MSE, TV)``
    (any may be ``None``), and the logged parts ``spec``, ``rgb``, ``real``, ``tv``."""
    parts: dict[str, float] = {}
    terms, tv_terms = [], []
    for key, group, weight in (("spec", g_spec, 1.0), ("rgb", g_rgb, tcfg.rgb_weight),
                               ("real", g_real, tcfg.real_weight)):
        if group is not None:
            mse, tv = group
            terms.append(weight * mse)
            tv_terms.append(tv)
            parts[key] = float(mse.detach())
    l_tv = torch.stack(tv_terms).mean()
    parts["tv"] = float(l_tv.detach())
    return sum(terms) + tcfg.tv_weight * l_tv, parts


def _step_batches(tcfg: TrainConfig, mcfg: Config, spectral: MaterialSet, rgb: MaterialSet,
                  dctx: ddp.DistContext | None, step: int) -> tuple[Batch | None, Batch | None]:
    """:func:`make_step_batches` with the step last (a picklable partial for spawned data workers)."""
    return make_step_batches(tcfg, mcfg, spectral, rgb, step, dctx)


def make_step_batches(tcfg: TrainConfig, mcfg: Config, spectral: MaterialSet, rgb: MaterialSet,
                      step: int, dctx: ddp.DistContext | None = None) -> tuple[Batch | None, Batch | None]:
    """The spectral and RGB batches of ``step``: a pure function of ``(seed, step)``.

    With a data-parallel ``dctx`` only the rank's own materials get their targets evaluated.
    """
    rng = np.random.default_rng([tcfg.seed, step])
    out: list[Batch | None] = []
    for mset, k, is_spec in ((spectral, tcfg.spectral_materials_per_step, True),
                             (rgb, tcfg.rgb_materials_per_step, False)):
        if len(mset) == 0 or k <= 0:
            out.append(None)
            continue
        mats, imgs = _draw(rng, mset, k, tcfg.canonical_fraction, tcfg.input_variants, tcfg.lighting)
        if tcfg.input_jitter_px > 0 or tcfg.input_scale_jitter > 0:
            # (no draws when off: earlier runs keep their data bit for bit)
            from specgen_addon.train.augment import jitter_framing

            imgs = [jitter_framing(im, rng, tcfg.input_jitter_px, tcfg.input_scale_jitter) for im in imgs]
        if tcfg.input_offgrid_fraction > 0:
            from specgen_addon.train.augment import offgrid_photo_crop

            imgs = [offgrid_photo_crop(im, rng, tcfg.input_finder_error_px)
                    if rng.random() < tcfg.input_offgrid_fraction else im for im in imgs]
        mine = ddp.shard_rows(len(mats), dctx) if dctx is not None and dctx.parallel else None
        out.append(make_batch(mats, imgs, rng, tcfg.angles_per_material, tcfg.wavelengths_per_angle,
                              is_spec, TARGET_WAVELENGTHS_NM, mcfg.mu, evaluate=mine))
    return out[0], out[1]


def _validation_batch(tcfg: TrainConfig, mcfg: Config, val: MaterialSet) -> Batch | None:
    if len(val) == 0:
        return None
    rng = np.random.default_rng([tcfg.seed, 1_000_003])
    mats = val.materials[: tcfg.val_materials]
    imgs = [np.asarray(val.images[i][0], dtype=np.float32) for i in range(len(mats))]
    return make_batch(mats, imgs, rng, tcfg.angles_per_material, tcfg.wavelengths_per_angle, True,
                      TARGET_WAVELENGTHS_NM, mcfg.mu)


def train(mcfg: Config, tcfg: TrainConfig, spectral: MaterialSet, rgb: MaterialSet, val: MaterialSet,
          out_dir: str | Path, resume: bool = False, show_progress: bool = True,
          meta: dict[str, Any] | None = None,
          on_step: Callable[[int, dict[str, float]], None] | None = None,
          real: Any = None) -> TrainResult:
    """Train SpecGen; writes ``checkpoint.pt``, ``history.csv`` and ``specgen.pt`` into ``out_dir``.

    With ``resume`` an existing checkpoint in ``out_dir`` is continued (same configs required).
    ``max_minutes`` stops this call early at a step boundary (the weights then say how many steps
    ran); a resumed run's earlier calls do not count against it. ``real``: the real RGB
    materials (:class:`.real_rgb.RealSource`); by default built from the config when it asks for them.
    """
    if len(spectral) == 0 and len(rgb) == 0:
        raise SpecGenError("no training materials")
    if real is None and tcfg.real_materials_per_step > 0:
        real = real_source(tcfg, cache_root() / "train-data", log=print if show_progress else (lambda _m: None))
    if tcfg.family_draw is not None:  # once, before any output and before data workers fork
        spectral, rgb = (dataclasses.replace(m, draw_p=family_draw_probabilities(m.materials, tcfg.family_draw))
                         if len(m) else m for m in (spectral, rgb))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(tcfg.threads)
    dctx = ddp.context()  # rank/world size under torchrun; 0 of 1 otherwise
    device = ddp.train_device(tcfg.device)
    # Bit-identical runs on the CPU. On a GPU the backward passes of grid_sample and bilinear
    # interpolation accumulate with atomics and have no deterministic kernel, so a run there is
    # reproducible only to float rounding.
    torch.use_deterministic_algorithms(device.type == "cpu")
    check_frozen(mcfg, tcfg)
    torch.manual_seed(tcfg.seed)
    model = SpecGen(mcfg)
    if tcfg.init_weights is not None and not (resume and (out / "checkpoint.pt").is_file()):
        init = load_weights(tcfg.init_weights)
        if not can_grow(init.cfg, mcfg, fresh_encoder=tcfg.fresh_encoder):
            raise SpecGenError(f"{tcfg.init_weights}: weights were made with a different model config")
        model.load_state_dict(grow_state_dict(init.state_dict(), init.cfg, mcfg, fresh=model.state_dict(),
                                              fresh_encoder=tcfg.fresh_encoder))
    model.to(device)  # before the optimiser, so its state lives there too
    for name in tcfg.frozen:
        getattr(model, name).requires_grad_(False)
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=tcfg.lr, betas=(0.9, 0.999))
    ema = None
    if tcfg.ema_decay > 0:
        from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

        ema = AveragedModel(model, multi_avg_fn=get_ema_multi_avg_fn(tcfg.ema_decay), use_buffers=True)
    history: list[dict[str, float]] = []
    start_step, elapsed0 = 0, 0.0
    ckpt_path = out / "checkpoint.pt"
    ddp.check_shardable({"spectral_materials_per_step": min(tcfg.spectral_materials_per_step, len(spectral)),
                         "rgb_materials_per_step": min(tcfg.rgb_materials_per_step, len(rgb))}, dctx)
    ck = ddp.broadcast(torch.load(ckpt_path, map_location="cpu", weights_only=True)
                       if resume and dctx.is_main and ckpt_path.is_file() else None, dctx)
    if ck is not None:
        # keys that older checkpoints lack take their defaults
        saved = {"ema_decay": 0.0, "linear_loss_weight": 0.0, "input_jitter_px": 0.0,
                 "fresh_encoder": False, "frozen": [],
                 "input_scale_jitter": 0.0, "input_offgrid_fraction": 0.0, "input_finder_error_px": 0.07,
                 "recolour_p": 0.0, "material_balance": "mean", "balance_floor": 0.1,
                 "real_materials_per_step": 0, "real_weight": 1.0, "real_rgb_dir": None, "real_exclude": [],
                 "real_exposure_jitter": 0.0, "real_white_balance_jitter": 0.0, "corpus_train_limit": 0,
                 **retire_keys(ck["train_config"], RETIRED_KEYS, "checkpoint")}
        if Config.from_dict(ck["model_config"]) != mcfg or saved != _tdict(tcfg, ignore_budget=True):
            raise SpecGenError(f"{ckpt_path}: checkpoint was made with a different configuration")
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optimizer"])
        if ema is not None:
            ema.load_state_dict(ck["ema"])
        start_step, elapsed0, history = ck["step"], ck["elapsed"], ck["history"]
    val_batch = _validation_batch(tcfg, mcfg, val)
    loss_fn = functools.partial(group_loss, linear_weight=tcfg.linear_loss_weight,
                                balance=tcfg.material_balance, balance_floor=tcfg.balance_floor)
    step_losses = ddp.step_losses(model, loss_fn, dctx)  # this rank's share, DDP-averaged

    def checkpoint(step: int, elapsed: float) -> None:
        if not dctx.is_main:
            return
        payload = {"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step,
                   "elapsed": elapsed, "history": history, "model_config": mcfg.to_dict(),
                   "train_config": _tdict(tcfg, ignore_budget=True)}
        if ema is not None:
            payload["ema"] = ema.state_dict()
        with atomic_write(ckpt_path, overwrite=True) as tmp:
            torch.save(payload, tmp)
        _write_history(out / "history.csv", history)

    bar = None
    if show_progress and dctx.is_main:
        from tqdm import tqdm

        bar = tqdm(total=tcfg.steps, initial=start_step, desc="train", unit="step", dynamic_ncols=True,
                   mininterval=2.0)
    scored = model if ema is None else ema.module  # what validation scores and specgen.pt holds
    if tcfg.snapshot_every and dctx.is_main:
        (out / "snapshots").mkdir(exist_ok=True)
    t0 = time.perf_counter()
    step = start_step
    stopped = False
    with contextlib.closing(step_batches(functools.partial(_step_batches, tcfg, mcfg, spectral, rgb, dctx),
                                         start_step, tcfg.steps, tcfg.data_workers)) as batches:
        # (closing: the data workers, if any, stop however the loop ends)
        for b_spec, b_rgb in batches:
            # this call's time: a resumed run gets its own budget, whatever the earlier calls took
            if tcfg.max_minutes is not None and time.perf_counter() - t0 > 60.0 * tcfg.max_minutes:
                stopped = True
                break
            for g in opt.param_groups:
                g["lr"] = lr_at(tcfg, step)
            model.train()
            opt.zero_grad(set_to_none=True)
            g_real = None
            if real is not None:
                g_real = real_loss(model, real.batch(tcfg.seed, step, mcfg.image_size,
                                                     tcfg.angles_per_material, mcfg.mu))
            loss, parts = total_loss(tcfg, *step_losses(b_spec, b_rgb), g_real)
            rec: dict[str, float] = {"step": step + 1, "lr": lr_at(tcfg, step), **parts}
            loss.backward()
            opt.step()
            if ema is not None:
                ema.update_parameters(model)
            step += 1
            rec["loss"] = float(loss.detach())
            rec = ddp.mean_record(rec, dctx)
            if val_batch is not None and (step % tcfg.val_every == 0 or step == tcfg.steps):
                rec["val"] = evaluate_batch(scored, val_batch)
            rec["elapsed"] = elapsed0 + time.perf_counter() - t0
            history.append(rec)
            if on_step is not None:
                on_step(step, rec)
            if bar is not None:
                bar.update(1)
                post = {k: f"{rec[k]:.4g}" for k in ("loss", "spec", "rgb", "real", "tv") if k in rec}
                if "val" in rec:
                    post["val"] = f"{rec['val']:.4g}"
                bar.set_postfix(post, refresh=False)
            if step % tcfg.checkpoint_every == 0:
                checkpoint(step, rec["elapsed"])
            if tcfg.snapshot_every and step >= tcfg.snapshot_from and step % tcfg.snapshot_every == 0 \
                    and dctx.is_main:
                save_weights(scored, out / "snapshots" / f"step{step:06d}.pt",
                             meta={"steps": step, "train_config": _tdict(tcfg)})
    if bar is not None:
        bar.close()
    wall = elapsed0 + time.perf_counter() - t0
    if val_batch is not None and history and "val" not in history[-1]:
        history[-1]["val"] = evaluate_batch(scored, val_batch)
    checkpoint(step, wall)
    info = {"steps": step, "planned_steps": tcfg.steps, "wall_seconds": round(wall, 1),
            "seed": tcfg.seed, "parameters": count_parameters(model), "train_config": _tdict(tcfg),
            "final_val_mse": history[-1].get("val") if history else None, **(meta or {})}
    weights = save_weights(scored, out / "specgen.pt", meta=info) if dctx.is_main else out / "specgen.pt"
    return TrainResult(weights, step, wall, history, stopped)


@torch.no_grad()
def evaluate_batch(model: SpecGen, b: Batch) -> float:
    """Masked μ-law MSE of ``model`` on a batch (eval mode, no gradients)."""
    was = model.training
    model.eval()
    t = _tensors(b, _device_of(model))
    pred = model(t["images"], t["theta_h"], t["theta_d"], t["phi_d"], t["wavelength_nm"])
    model.train(was)
    return float(masked_mse(pred, t["target"], t["valid"]))


def _tdict(tcfg: TrainConfig, ignore_budget: bool = False) -> dict[str, Any]:
    d = dataclasses.asdict(tcfg)
    if ignore_budget:  # a resumed run may extend its budget or change what it logs
        for k in ("steps", "max_minutes", "threads", "checkpoint_every", "val_every", "init_weights",
                  "render_workers", "data_workers", "device", "snapshot_every", "snapshot_from"):
            d.pop(k)
    return d


def _write_history(path: Path, history: Sequence[dict[str, float]]) -> None:
    keys = ["step", "lr", "loss", "spec", "rgb", "real", "tv", "val", "elapsed"]
    with atomic_write(path, overwrite=True) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
            w.writeheader()
            for rec in history:
                w.writerow({k: rec.get(k, "") for k in keys})


def plot_history(history: Sequence[dict[str, float]], path: str | Path, title: str = "") -> Path:
    """Loss curve PNG: training losses (smoothed) and validation MSE against steps (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = np.array([r["step"] for r in history])
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for key, label in (("spec", "L_spec (train)"), ("rgb", "L_RGB (train)"), ("tv", "L_TV (train)")):
        vals = np.array([r.get(key, np.nan) for r in history], dtype=float)
        if np.all(np.isnan(vals)):
            continue
        k = max(1, len(vals) // 100)
        smooth = np.convolve(np.nan_to_num(vals), np.ones(k) / k, mode="valid")
        ax.plot(steps[k - 1:], smooth, label=label, lw=1.2)
    vs = [(r["step"], r["val"]) for r in history if "val" in r]
    if vs:
        ax.plot(*zip(*vs), "o-", ms=3, label="L_spec (validation)")
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("MSE in μ-law space")
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def validate_train_config(path: str | os.PathLike, overrides: dict[str, Any] | None = None) -> None:
    """Refuse a training config file (plus command-line ``overrides`` of train keys) that does not
    fit the schema, before any data is prepared."""
    data = read_config_dict(path)
    unknown = sorted(set(data) - {"model", "train"})
    if unknown:
        raise SpecGenError(f"{path}: unknown section(s) {', '.join(unknown)} (expected model, train)")
    validate_section(Config, data.get("model", {}), f"{path}: model", MODEL_BOUNDS, (1, None))
    train = data.get("train", {})
    if not isinstance(train, dict):
        raise type_error(f"{path}: train", "an object of settings", train)
    train = {**train, **(overrides or {})}
    validate_section(TrainConfig, train, f"{path}: train", TRAIN_BOUNDS)
    try:
        Config.from_dict(data.get("model", {}))
    except TypeError as exc:
        raise SpecGenError(f"{path}: model: {exc}") from None
