"""A photo's options, one definition for ``infer``, ``batch.py`` and each ``--apply`` photo.

:func:`add_photo_arguments` adds them to a parser (``infer`` and ``batch.py`` call the same
function, so their option sets cannot drift); :func:`parse_apply_options` and
:func:`apply_namespace` read one ``--apply`` photo's ``key=value`` list with the same
definitions, over the command's own values; :func:`photo_inputs` turns the values into the photo
(:class:`~specgen_addon.photo.sphere_image.PhotoSource`) and the light it was taken under (given,
a panorama, a chrome ball, or estimated from the ball) for every entry alike.
"""

from __future__ import annotations

import argparse
import copy
import functools
import os
import re
import sys
from pathlib import Path

from specgen_addon.brdf.formats.export import size_text
from specgen_addon.common.errors import SpecGenError
from specgen_addon.generate.models import DEFAULT_MODEL, MODELS
from specgen_addon.common.limits import check_input_file, check_output_file, refuse_existing
from specgen_addon.photo.image_checks import check_image_header
from specgen_addon.photo.light_estimate import estimated_lighting as estimate
from specgen_addon.photo.light_probe import (
    CHROME_REFLECTANCE,
    check_reflectance,
    lighting_from_probe,
    read_probe,
)
from specgen_addon.photo.photo_lighting import (
    AZIMUTH_RANGE,
    CANONICAL,
    ELEVATION_RANGE,
    MAX_AMBIENT,
    MAX_LIGHT_POWER,
    NO_MAP,
    parse_light,
    parse_lighting,
)
from specgen_addon.photo.read import check_white_level
from specgen_addon.photo.sphere_image import (
    PhotoSource,
    check_white_balance_choice,
    parse_circle,
    write_circle_preview,
)
from specgen_addon.photo.white_balance import parse_patch

#: ``--apply`` keys kept from before every photo option was a key: short names of the map options.
APPLY_ALIASES = {"env": "--input-env", "rotation": "--input-rotation", "exposure": "--input-exposure",
                 "key-light": "--input-key-light"}
_TRUE, _FALSE = {"on", "yes", "true", "1"}, {"off", "no", "false", "0"}


def add_photo_arguments(p: argparse.ArgumentParser) -> None:
    """The photo options: what makes the BRDF, the refinement, the photo's decoding, where the ball
    is, its white balance and the light it was taken under (``infer`` and ``batch.py`` alike)."""
    g = p.add_argument_group("photo consistency",
                             "the lighting the photo was taken under, and the refinement that makes "
                             "the BRDF reproduce the photo under it")
    g.add_argument("--model", choices=tuple(MODELS), default=DEFAULT_MODEL,
                   help="what makes the BRDF (default %(default)s): " + "; ".join(
                       f"'{name}': {choice.description}" for name, choice in MODELS.items()))
    g.add_argument("--refine", action=argparse.BooleanOptionalAction, default=True,
                   help="refine the network's BRDF so it reproduces the photo (default: on)")
    g.add_argument("--latent-fit", action="store_true",
                   help="before refinement, fit the network's own latent to the photo and decode the "
                        "table again (torch backend; about 25 s more on two cores; off by default: on "
                        "held-out photos it did not beat refinement alone, docs/refinement.md)")
    g.add_argument("--input-env", default="canonical", metavar="NAME|FILE",
                   help="lighting of the photo: 'canonical' (studio map + key light, default), a "
                        "bundled map name (forest, courtyard, ...), an .exr/.hdr file, or 'estimate': "
                        "a few distant lights + ambient estimated from the ball's own shading")
    g.add_argument("--input-rotation", type=float, default=0.0, metavar="DEG",
                   help="rotation of the input map about the up axis, degrees (default 0)")
    g.add_argument("--input-exposure", type=float, default=1.0,
                   help="input map brightness relative to the canonical level (default 1)")
    g.add_argument("--input-key-light", action=argparse.BooleanOptionalAction, default=None,
                   help="add the canonical D65 key light to a map (default: only for canonical)")
    g.add_argument("--input-env-calibrated", action="store_true",
                   help="the --input-env panorama holds radiance as photographed: use its values as "
                        "they are (no normalisation to unit mean; --input-exposure still multiplies)")
    g.add_argument("--light", action="append", default=[], metavar="AZ,EL[,POWER[,COLOUR]]",
                   help="a distant light (or the sun) of the room, by azimuth and elevation in degrees "
                        f"in the camera's frame (azimuth {AZIMUTH_RANGE[0]:g} to {AZIMUTH_RANGE[1]:g}, 0 "
                        "faces the camera, +90 is to the right; elevation "
                        f"{ELEVATION_RANGE[0]:g} to {ELEVATION_RANGE[1]:g}, +90 is up), power (1: the "
                        f"canonical key light; at most {MAX_LIGHT_POWER:,.0f}) and colour (a CIE "
                        "illuminant such as D65 or A, a temperature such as 3200K, or linear RGB "
                        "such as 1/0.8/0.6); repeatable. "
                        "Without --input-env the lights (and --ambient) alone light the photo")
    g.add_argument("--light-vector", action="append", default=[], metavar="X,Y,Z[,POWER[,COLOUR]]",
                   help="a distant light by its direction in the camera's frame (x right, y up, z "
                        "towards the camera), as --light; repeatable")
    g.add_argument("--ambient", type=float, default=0.0, metavar="L",
                   help="uniform ambient radiance of the room (1: the radiance of a white surface "
                        f"facing the canonical key light; at most {MAX_AMBIENT:,.0f}; default 0)")
    g.add_argument("--light-probe", type=Path, default=None, metavar="CHROME",
                   help="a photo of a chrome (mirror) ball from the same place under the same light, "
                        "taken like the photo: unwrapped into the room's environment in the camera's frame "
                        "(Debevec 1998; written beside the output as OUTPUT_probe.exr), its clipped "
                        "light sources made distant lights with their power fitted to the photo")
    g.add_argument("--probe-mask", type=Path, default=None, metavar="FILE",
                   help="mask of the chrome ball in --light-probe (the ball white)")
    g.add_argument("--probe-circle", default=None, metavar="X,Y,R",
                   help="the chrome ball's centre and radius in --light-probe's pixels")
    g.add_argument("--probe-reflectance", type=float, default=None, metavar="R",
                   help=f"the chrome ball's reflectance, in (0, 1] (default {CHROME_REFLECTANCE:g})")
    g.add_argument("--linear", action="store_true",
                   help="the photo's 8/16-bit values are linear light (a linear export of a RAW, a "
                        "scientific camera); default: sRGB-encoded. EXR/HDR are always linear and "
                        "camera RAW files are developed linearly")
    g.add_argument("--white-level", type=float, default=None, metavar="V",
                   help="values at or above V (linear, as decoded) count as saturated and are left out "
                        "of every fit: for EXR/HDR, which have no full scale; 8/16-bit files and RAW "
                        "are also checked at their own full scale")
    g.add_argument("--white-patch", default=None, metavar="X,Y,W,H",
                   help="white balance: a neutral patch of the photo (a grey card, a white wall), its "
                        "top-left corner and size in pixels (x right, y down); the photo is scaled so "
                        "the patch has the colour of the light the run assumes (neutral for D65 or a "
                        "chrome ball; a --light-probe photo gets the same gains). Default: as shot")
    g.add_argument("--colour-checker", action="store_true",
                   help="white balance from an X-Rite ColorChecker Classic in the photo: found "
                        "(colour-checker-detection, OpenCV; command line only), its six greys fitted to "
                        "the chart's reference greys under the light the run assumes, as --white-patch "
                        "(not with --white-patch)")
    g.add_argument("--circle", default=None, metavar="X,Y,R",
                   help="the sphere's centre and radius in the photo's pixels (x right, y down from the "
                        "top-left corner) instead of finding it")
    g.add_argument("--mask", type=Path, default=None, metavar="FILE",
                   help="a mask image of the photo's size, the sphere white (or opaque): its circle is used")
    g.add_argument("--circle-preview", type=Path, default=None, metavar="PNG",
                   help="write the photo with the circle used drawn on it (8-bit sRGB PNG, a name "
                        "ending in .png)")


@functools.lru_cache(maxsize=1)
def _photo_actions() -> dict[str, argparse.Action]:
    """``--apply`` key → the argparse action of that photo option (each long flag without ``--``,
    plus :data:`APPLY_ALIASES`)."""
    p = argparse.ArgumentParser(add_help=False)
    add_photo_arguments(p)
    by_flag = {s: a for a in p._actions for s in a.option_strings if s.startswith("--")}
    keys = {a.option_strings[0][2:]: a for a in p._actions if a.option_strings}
    keys.update({k: by_flag[flag] for k, flag in APPLY_ALIASES.items()})
    return keys


def photo_dests() -> set[str]:
    """The namespace names of every photo option (what ``infer``, ``batch.py`` and ``--apply`` share)."""
    return {a.dest for a in _photo_actions().values()}


def apply_keys() -> list[str]:
    """Every key an ``--apply`` photo takes."""
    return sorted(_photo_actions())


def _takes_commas(action: argparse.Action) -> bool:
    return "," in str(action.metavar or "")


def split_apply(spec: str) -> tuple[str, str]:
    """``IMG:OBJECT[:OPTIONS]`` → (``IMG:OBJECT``, ``OPTIONS``). The options start at the first ``:``
    followed by a known ``key=`` (so a Windows path in a value is fine), else at the last ``:`` when
    what follows holds an ``=``."""
    keys = "|".join(re.escape(k) for k in sorted(_photo_actions(), key=len, reverse=True))
    m = re.search(rf":(?=\s*(?:{keys})\s*=)", spec)
    if m is not None:
        return spec[:m.start()], spec[m.end():]
    first, sep, last = spec.rpartition(":")
    if sep and "=" in last:
        return first, last
    return spec, ""


def parse_apply_options(spec: str, text: str) -> tuple[tuple[str, object], ...]:
    """One ``--apply`` photo's ``key=value,...`` as ``(dest, value)`` pairs, each value converted and
    checked as the command-line option of the same name would be. A value that itself holds commas
    (``light=30,20,2``, ``circle=X,Y,R``) runs on up to the next ``key=``."""
    actions = _photo_actions()
    items: list[str] = []
    for part in text.split(","):
        prev = actions.get(items[-1].partition("=")[0].strip().lower()) if items else None
        if "=" not in part and prev is not None and _takes_commas(prev):
            items[-1] += "," + part
            continue
        items.append(part)
    out: list[tuple[str, object]] = []
    seen: set[str] = set()
    for item in items:
        key, eq, value = item.partition("=")
        key, value = key.strip().lower(), value.strip()
        if not eq:
            raise SpecGenError(f"--apply {spec!r}: options are key=value pairs separated by commas")
        action = actions.get(key)
        if action is None:
            raise SpecGenError(f"--apply {spec!r}: unknown option {key!r} (known: {', '.join(apply_keys())})")
        repeatable = isinstance(action, argparse._AppendAction)
        if action.dest in seen and not repeatable:
            raise SpecGenError(f"--apply {spec!r}: option {key!r} is given twice")
        seen.add(action.dest)
        out.append((action.dest, _convert(spec, key, value, action)))
    return tuple(out)


def _convert(spec: str, key: str, value: str, action: argparse.Action):
    """A ``--apply`` value as its option's type (on/off for switches), or one sentence why not."""
    if isinstance(action, (argparse._StoreTrueAction, argparse.BooleanOptionalAction)):
        if value.lower() not in _TRUE | _FALSE:
            raise SpecGenError(f"--apply {spec!r}: {key} must be on or off, not {value!r}")
        return value.lower() in _TRUE
    if not value:
        raise SpecGenError(f"--apply {spec!r}: {key} needs a value")
    if action.choices is not None and value not in action.choices:
        raise SpecGenError(f"--apply {spec!r}: {key} must be one of {', '.join(action.choices)}, not {value!r}")
    if action.type is float:
        try:
            return float(value)
        except ValueError:
            raise SpecGenError(f"--apply {spec!r}: {key} must be a number, not {value!r}") from None
    return action.type(value) if action.type is not None else value


def apply_namespace(base: argparse.Namespace, options) -> argparse.Namespace:
    """The command's values with one photo's ``--apply`` options over them (a repeatable option
    given there, such as ``light``, replaces the command's list)."""
    ns = copy.copy(base)
    lists = {a.dest for a in _photo_actions().values() if isinstance(a, argparse._AppendAction)}
    replaced: set[str] = set()
    for dest, value in options:
        if dest in lists:
            value = (list(getattr(ns, dest)) if dest in replaced else []) + [value]
            replaced.add(dest)
        setattr(ns, dest, value)
    return ns


# -- from values to the photo and its light ------------------------------------------------------

def input_lighting_from_args(args: argparse.Namespace):
    """The validated :class:`InputLighting` of the lighting options (lights, map, ambient)."""
    lights = tuple(parse_light(t) for t in getattr(args, "light", None) or []) + \
        tuple(parse_light(t, vector=True) for t in getattr(args, "light_vector", None) or [])
    return parse_lighting(args.input_env, args.input_rotation, args.input_exposure, args.input_key_light,
                          lights=lights, ambient=float(getattr(args, "ambient", 0.0) or 0.0),
                          calibrated=bool(getattr(args, "input_env_calibrated", False)))


def photo_source_from_args(args: argparse.Namespace, image: Path, white_target=None):
    """The :class:`~specgen_addon.photo.sphere_image.PhotoSource` of a photo and the photo options;
    ``white_target`` (linear RGB) is the colour ``--white-patch`` or ``--colour-checker`` balances to
    (default neutral)."""
    for circle, mask in (("circle", "mask"), ("probe_circle", "probe_mask")):   # one way to place a ball
        if getattr(args, circle, None) and getattr(args, mask, None) is not None:
            raise SpecGenError(f"--{circle.replace('_', '-')} and --{mask.replace('_', '-')} both place "
                               "the ball: give one")
    circle = getattr(args, "circle", None)
    patch = getattr(args, "white_patch", None)
    return PhotoSource(Path(image), encoding="linear" if getattr(args, "linear", False) else "auto",
                       white_level=getattr(args, "white_level", None),
                       circle=parse_circle(circle) if circle else None, mask=getattr(args, "mask", None),
                       white_patch=parse_patch(patch) if patch else None,
                       white_target=None if white_target is None else tuple(float(v) for v in white_target),
                       colour_checker=bool(getattr(args, "colour_checker", False)))


#: The lighting and chrome-ball options whose use depends on the others, each with its value when
#: not given.
_DEFAULTS = {"--light": [], "--light-vector": [], "--ambient": 0.0, "--input-key-light": None,
             "--input-rotation": 0.0, "--input-exposure": 1.0, "--input-env-calibrated": False,
             "--light-probe": None, "--probe-mask": None, "--probe-circle": None, "--probe-reflectance": None}
#: Options that describe the light in the photo, and options of an --input-env map.
_LIGHT_FLAGS = ("--light", "--light-vector", "--ambient", "--input-key-light")
_MAP_FLAGS = ("--input-rotation", "--input-exposure", "--input-env-calibrated")


def _given(args: argparse.Namespace, *flags: str) -> list[str]:
    """Those of ``flags`` (keys of :data:`_DEFAULTS`) that ``args`` sets to anything but their default."""
    return [f for f in flags
            if getattr(args, f[2:].replace("-", "_"), _DEFAULTS[f]) not in (_DEFAULTS[f], None)]


def _and(flags: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return " and ".join([", ".join(flags[:-1]), flags[-1]] if len(flags) > 1 else flags)


def _unused(flags: list[str], applies: str, remedy: str) -> SpecGenError:
    """One sentence refusing options that do not apply: ``--a applies to …: remedy, or leave it out``
    (``apply``, ``them`` for several)."""
    one = len(flags) == 1
    return SpecGenError(f"{_and(flags)} {'applies' if one else 'apply'} to {applies}: {remedy}, or leave "
                        f"{'it' if one else 'them'} out")


def _lighting_mode(args: argparse.Namespace) -> str:
    """``"estimate"``, ``"probe"`` or ``"given"``; an option that conflicts with the choice or does
    not apply to it, and a chrome ball's reflectance or circle out of range, refused in one sentence."""
    probe_options = _given(args, "--probe-mask", "--probe-circle", "--probe-reflectance")
    probe = getattr(args, "light_probe", None) is not None
    if probe_options and not probe:
        raise _unused(probe_options, "the chrome ball of --light-probe", "give --light-probe")
    if args.input_env == "estimate":
        needless = _given(args, *_LIGHT_FLAGS, *_MAP_FLAGS, "--light-probe")
        if needless:
            raise SpecGenError(f"--input-env estimate finds the light itself: leave out {_and(needless)}")
        return "estimate"
    if probe:
        needless = _given(args, *_LIGHT_FLAGS, *_MAP_FLAGS) + \
            ([] if args.input_env in (None, "", CANONICAL) else ["--input-env"])
        if needless:
            raise SpecGenError(f"--light-probe gives the room's light: leave out {_and(needless)}")
        if getattr(args, "probe_reflectance", None) is not None:
            check_reflectance(args.probe_reflectance)
        if getattr(args, "probe_circle", None):
            parse_circle(args.probe_circle, "--probe-circle")
        return "probe"
    map_options = _given(args, "--input-rotation", "--input-exposure")
    if map_options and args.input_env in (None, "", CANONICAL, NO_MAP):
        raise _unused(map_options, "an --input-env map", "name a bundled map or a panorama file")
    if getattr(args, "input_key_light", None) is False and args.input_env in (None, "", CANONICAL):
        raise SpecGenError("--no-input-key-light applies to an --input-env map (the canonical studio "
                           "always has its key light): leave it out")
    return "given"


def check_photo_options(args: argparse.Namespace):
    """Everything about the photo options that needs neither the photo nor the network (what
    batch-many checks for every item before any runs): the lighting options and how they combine,
    the lights' and the chrome ball's values, ``--circle`` and ``--white-patch`` as numbers, one
    white balance, the white level, the mask and chrome-ball files readable. Gives the lighting
    mode (:func:`_lighting_mode`) and, for ``"given"``, the lighting (else None)."""
    mode = _lighting_mode(args)
    lighting = input_lighting_from_args(args) if mode == "given" else None
    source = photo_source_from_args(args, Path(os.devnull))    # parses --circle and --white-patch
    check_white_balance_choice(source.white_patch, source.colour_checker)
    check_white_level(getattr(args, "white_level", None))
    for option, what in (("mask", "--mask file"), ("light_probe", "--light-probe photo"),
                         ("probe_mask", "--probe-mask file")):
        if getattr(args, option, None) is not None:
            _check_image_file(getattr(args, option), what)
    return mode, lighting


def check_photo_args(args: argparse.Namespace, image: Path, outputs: dict[str, Path] | None = None,
                     out_dir: Path | None = None) -> None:
    """Everything about one photo's options that needs no network: the photo read and its ball
    found (with ``--circle``/``--mask``/``--linear``), the white patch in the photo, the light's
    values, the probe file there, the preview not in the way of the photo or of the run's other
    ``outputs`` (:func:`check_circle_preview`; ``out_dir``: the output folder the run makes first)."""
    mode, lighting = check_photo_options(args)            # the chrome ball's file included
    check_circle_preview(args, image, outputs or {}, out_dir)
    crop = photo_source_from_args(args, image, _white_target(lighting)).crop()
    if mode == "probe":   # found and unwrapped now (a fraction of a second), not after the scene opens
        _read_probe(args, "auto" if not getattr(args, "linear", False) else "linear", crop.white_gains)


def check_probe_file(path: Path) -> None:
    """The ``--light-probe`` photo: a readable file within the pixel limit, else one sentence."""
    _check_image_file(path, "--light-probe photo")


def _check_image_file(path: Path, what: str) -> None:
    """An image file an option names (``what``): readable, within the pixel limit; else one sentence."""
    check_input_file(path, what)
    check_image_header(path)


def check_circle_preview(args: argparse.Namespace, image: Path, outputs: dict[str, Path],
                         out_dir: Path | None = None) -> None:
    """``--circle-preview``: a ``.png`` name (not a folder) in an existing, writable folder (or in
    ``out_dir``, the output folder the run makes before it writes the preview), new or replaced
    with ``--overwrite``, and neither the photo, nor a file the options read, nor one of the run's
    other ``outputs`` (what each is, as the message names it → its path)."""
    preview = getattr(args, "circle_preview", None)
    if preview is None:
        return
    preview = Path(preview)
    read = {"the photo": image, "--mask": getattr(args, "mask", None),
            "--light-probe": getattr(args, "light_probe", None),
            "--probe-mask": getattr(args, "probe_mask", None)}
    for what, other in {**read, **outputs}.items():
        if other is not None and _same_file(preview, Path(other)):
            raise SpecGenError(f"--circle-preview {preview} is the same file as {what} {other}")
    made_first = (out_dir is not None and not Path(out_dir).exists()
                  and _same_file(preview.parent, Path(out_dir)))
    if not made_first:
        check_output_file(preview, getattr(args, "overwrite", False))
    if preview.suffix.lower() != ".png":
        raise SpecGenError(f"--circle-preview writes a PNG, so its name must end in .png, got {preview}")


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (through links, and before either exists)."""
    if a.exists() and b.exists():
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def _read_probe(args: argparse.Namespace, encoding: str, gains):
    reflectance = CHROME_REFLECTANCE if args.probe_reflectance is None else args.probe_reflectance
    return read_probe(args.light_probe, circle=parse_circle(args.probe_circle, "--probe-circle") if args.probe_circle else None,
                      mask=args.probe_mask, encoding=encoding, reflectance=reflectance, gains=gains)


def _white_target(lighting):
    """The colour a white patch is balanced to: a white surface's under ``lighting`` (None:
    neutral, for a light estimated or unwrapped from a chrome ball photographed alike)."""
    return None if lighting is None else lighting.white_sphere_rgb()


def photo_inputs(args: argparse.Namespace, image: Path, probe_env: Path):
    """(PhotoSource, InputLighting) of a photo and its options: the light given, estimated from
    the ball (``--input-env estimate``) or unwrapped from ``--light-probe`` (its environment
    written to ``probe_env``); what was estimated or unwrapped is printed."""
    mode = _lighting_mode(args)
    if mode == "given":
        lighting = input_lighting_from_args(args)
        return photo_source_from_args(args, image, _white_target(lighting)), lighting
    source = photo_source_from_args(args, image)
    if mode == "estimate":
        return source, estimated_lighting(source)
    return source, probe_lighting_from_args(args, source, probe_env)


def estimated_lighting(source):
    """``--input-env estimate``: distant lights + ambient estimated from the ball itself
    (:func:`specgen_addon.photo.light_estimate.estimated_lighting`); the run says so, with the
    model's residual."""
    lighting, text = estimate(source)
    print(f"input lighting {text}")
    return lighting


def probe_lighting_from_args(args: argparse.Namespace, source, env_path: Path):
    """The lighting unwrapped from ``--light-probe`` (:func:`specgen_addon.photo.light_probe.lighting_from_probe`),
    its environment written to ``env_path``; the photo's white-balance gains applied to the probe
    too (same camera); the run's notes about it printed."""
    overwrite = getattr(args, "overwrite", False)
    check_probe_file(args.light_probe)
    refuse_existing(env_path, overwrite)
    env_path.parent.mkdir(parents=True, exist_ok=True)
    lighting, notes = lighting_from_probe(args.light_probe, source, env_path,
                                          circle=parse_circle(args.probe_circle, "--probe-circle") if args.probe_circle else None,
                                          mask=args.probe_mask, reflectance=args.probe_reflectance,
                                          overwrite=overwrite)
    for note in notes:
        print(f"light probe: {note}")
    print(f"wrote {env_path} (the room's environment unwrapped from the chrome ball, camera frame, "
          f"{size_text(env_path.stat().st_size)})")
    return lighting


# -- what a run reports --------------------------------------------------------------------------

def print_photo_report(generated, args: argparse.Namespace, source) -> None:
    """The circle used (and the preview with it drawn), the white balance, and the network's
    self-reproduction when there was no refinement to report it."""
    crop = generated.crop
    if crop is not None:
        print(crop.describe())
        if crop.white_note:
            print(crop.white_note)
        preview = getattr(args, "circle_preview", None)
        if preview is not None and crop.circle is not None:
            write_circle_preview(preview, source, crop.circle, overwrite=getattr(args, "overwrite", False))
            print(f"wrote {preview} (the photo with the circle used, {size_text(Path(preview).stat().st_size)})")
    if getattr(generated, "canonical_input", None) is not None:
        print(generated.canonical_input.describe())
    if generated.network_reproduction is not None:
        print(f"self-reproduction of the network alone under "
              f"{generated.table.metadata.get('input_lighting', 'the input lighting')}: "
              f"{generated.network_reproduction.text()} (no refinement)")


def print_refinement(generated) -> None:
    """One line on what refinement reached, and its warnings (on stderr)."""
    res = generated.refinement
    if res is not None:
        kept = "" if res.improved else " (network's table kept)"
        print(f"refinement under {res.table.metadata.get('refine_lighting', 'the input lighting')}: "
              f"{res.summary()}{kept}")
    for w in generated.warnings:
        print(f"warning: {w}", file=sys.stderr)
