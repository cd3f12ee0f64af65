"""Typed schema of the training config file (``{"model": {...}, "train": {...}}``).

Checked before any data preparation: every key must be a field of
:class:`~specgen_addon.model.Config` or :class:`~specgen_addon.train.loop.TrainConfig`, every
value of that field's declared type (``"steps": "ten"`` is refused, ``true`` is not an int) and
inside its bounds (:data:`TRAIN_BOUNDS`; NaN and ±Inf never pass). The message names the file, the
section, the key, what was expected and what was found. No torch is imported here.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any

from specgen_addon.common.errors import SpecGenError

#: (lowest, highest) of numeric training knobs; ``None`` = unbounded on that side.
TRAIN_BOUNDS: dict[str, tuple[float | None, float | None]] = {
    "seed": (0, 2**32 - 1), "steps": (1, 10_000_000), "max_minutes": (0.01, 100_000.0),
    "lr": (1e-8, 1.0), "lr_decay_every": (1, None), "lr_decay": (1e-6, 1.0),
    "spectral_materials_per_step": (1, 4096), "rgb_materials_per_step": (0, 4096),
    "angles_per_material": (1, 1 << 20), "wavelengths_per_angle": (1, 512),
    "tv_weight": (0.0, 1e6), "rgb_weight": (0.0, 1e6), "linear_loss_weight": (0.0, 1e6),
    "balance_floor": (1e-6, 1e3),
    "input_jitter_px": (0.0, 8.0), "input_scale_jitter": (0.0, 0.5),
    "input_offgrid_fraction": (0.0, 1.0), "input_finder_error_px": (0.0, 2.0), "corpus_size": (1, 100_000),
    "corpus_seed": (0, 2**32 - 1), "input_variants": (1, 1000), "canonical_fraction": (0.0, 1.0),
    "checkpoint_every": (1, None), "val_every": (1, None), "val_materials": (0, 10_000),
    "threads": (1, 256), "ema_decay": (0.0, 0.999999),
    "snapshot_every": (0, None), "snapshot_from": (0, None), "render_workers": (1, 256),
    "data_workers": (0, 256), "real_materials_per_step": (0, 4096), "real_weight": (0.0, 1e6),
    "real_exposure_jitter": (0.0, 4.0), "real_white_balance_jitter": (0.0, 1.0),
    "corpus_train_limit": (0, 10_000_000),
}
#: Numeric model sizes are at least 1 (and finite); these have other bounds.
MODEL_BOUNDS: dict[str, tuple[float | None, float | None]] = {
    "image_size": (8, 1024), "lambda_min_nm": (300.0, 1100.0), "lambda_max_nm": (300.0, 1100.0),
    "mu": (1e-3, 1e6), "latent_res_blocks": (0, 64), "trunk_res_blocks": (0, 64),
    "trunk_upsample_stages": (0, 4), "encoder_negative_slope": (0.0, 0.999),
}


def type_error(where: str, expected: str, value: Any) -> SpecGenError:
    """The one-sentence error for a setting of the wrong type (``where`` names the setting)."""
    return SpecGenError(f"{where} must be {expected}, got {json.dumps(value, default=str)} "
                        f"({type(value).__name__})")


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_value(where: str, annotation: str, value: Any,
                 bounds: tuple[float | None, float | None] | None) -> None:
    ann = annotation.replace(" ", "")
    if ann.endswith("|None"):
        if value is None:
            return
        ann = ann[:-5]
    if ann == "bool":
        if not isinstance(value, bool):
            raise type_error(where, "true or false", value)
        return
    if ann == "str":
        if not isinstance(value, str):
            raise type_error(where, "a string", value)
        return
    if ann.startswith(("tuple[", "list[")):
        item = ann[ann.index("[") + 1:-1].split(",")[0]
        if not isinstance(value, (list, tuple)) or not value:
            raise type_error(where, f"a non-empty list of {item}", value)
        for i, v in enumerate(value):
            _check_value(f"{where}[{i}]", item, v, bounds if item != "str" else None)
        return
    if ann == "int":
        if not _is_int(value):
            raise type_error(where, "a whole number", value)
    elif ann == "float":
        if not _is_number(value):
            raise type_error(where, "a number", value)
    if _is_number(value):
        if not math.isfinite(value):
            raise SpecGenError(f"{where} must be a finite number, got {value}")
        lo, hi = bounds or (None, None)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            f = (lambda x: f"{x:,}" if isinstance(x, int) else f"{x:g}")
            rng = f"between {f(lo)} and {f(hi)}" if lo is not None and hi is not None else \
                f"at least {f(lo)}" if lo is not None else f"at most {f(hi)}"
            raise SpecGenError(f"{where} must be {rng}, got {f(value)}")


def validate_section(cls, data: Any, where: str,
                     bounds: dict[str, tuple[float | None, float | None]],
                     default_bounds: tuple[float | None, float | None] | None = None) -> None:
    """Check ``data`` (a JSON object) against dataclass ``cls``'s fields, types and ``bounds``."""
    if not isinstance(data, dict):
        raise type_error(where, "an object of settings", data)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise SpecGenError(f"{where}: unknown key(s) {', '.join(unknown)} "
                           f"(known: {', '.join(sorted(fields))})")
    for key, value in data.items():
        _check_value(f"{where}.{key}", str(fields[key].type), value, bounds.get(key, default_bounds))


#: The top-level key by which a config file names the file it extends.
EXTENDS_KEY = "extends"
#: How many files one chain of ``extends`` may hold (a guard, far above any real chain).
MAX_EXTENDS_DEPTH = 16


def read_config_dict(path: str | os.PathLike) -> dict:
    """The config object of a JSON or TOML file, its bases merged in; one clear error for a missing,
    unreadable or unparsable file.

    A file may name a base, ``"extends": "continue_s50_recolour.json"`` (relative to its own folder),
    so that a continuation states only what changes: its ``model`` and ``train`` keys override the
    base's key by key, and an object value (``families``, ``family_draw``) replaces the base's whole
    object, since those are distributions. A relative ``init_weights`` is made absolute against the
    folder of the file that names it, so a base keeps meaning the same weights wherever it is used.
    """
    return _resolve_extends(Path(path), ())


def _resolve_extends(path: Path, chain: tuple[Path, ...]) -> dict:
    data = _read_config_file(path)
    _absolute_init_weights(data, path.parent)
    if EXTENDS_KEY not in data:
        return data
    base_name = data.pop(EXTENDS_KEY)
    if not isinstance(base_name, str) or not base_name:
        raise type_error(f"{path}: {EXTENDS_KEY}", "the path of a base config file", base_name)
    base = (path.parent / base_name).resolve()
    here = (*chain, path.resolve())
    if base in here:
        names = " → ".join(p.name for p in (*here, base))
        raise SpecGenError(f"{path}: {EXTENDS_KEY} {base_name} makes a cycle ({names})")
    if len(here) >= MAX_EXTENDS_DEPTH:
        raise SpecGenError(f"{path}: {EXTENDS_KEY} chain is longer than {MAX_EXTENDS_DEPTH} files")
    if not base.is_file():
        raise SpecGenError(f"{path}: {EXTENDS_KEY} {base_name}: config file not found")
    return _merge_sections(_resolve_extends(base, here), data)


def _merge_sections(base: dict, over: dict) -> dict:
    """``base`` with ``over``'s sections laid on it key by key (values replace, objects too)."""
    merged = {k: dict(v) if isinstance(v, dict) else v for k, v in base.items()}
    for section, values in over.items():
        if isinstance(values, dict) and isinstance(merged.get(section), dict):
            merged[section].update(values)
        else:
            merged[section] = values
    return merged


def _absolute_init_weights(data: dict, folder: Path) -> None:
    train = data.get("train")
    init = train.get("init_weights") if isinstance(train, dict) else None
    if isinstance(init, str) and init and not Path(init).is_absolute():
        train["init_weights"] = str((folder / init).resolve())


def _read_config_file(path: Path) -> dict:
    """One config file's object as written (no bases)."""
    if path.is_dir():
        raise SpecGenError(f"{path}: is a folder, expected a config file (.json or .toml)")
    if not path.exists():
        raise SpecGenError(f"{path}: config file not found")
    if not path.is_file():  # a device or a named pipe
        raise SpecGenError(f"{path}: is not a regular file (config file)")
    try:
        text = path.read_text(encoding="utf-8")
    except PermissionError:
        raise SpecGenError(f"{path}: config file is not readable (permission denied)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecGenError(f"{path}: cannot read config ({exc})") from None
    try:
        if path.suffix.lower() == ".toml":
            import tomllib

            data = tomllib.loads(text)
        else:
            data = json.loads(text)  # accepts NaN: refused below as "not finite"
    except ValueError as exc:
        raise SpecGenError(f"{path}: cannot parse config ({exc})") from None
    if not isinstance(data, dict):
        raise SpecGenError(f"{path}: a config file holds an object with 'model' and 'train' sections")
    return data
