"""A photo's options are one definition: `infer`, batch.py and each `--apply` photo take the same
set, read them the same way, and refuse the same mistakes in one sentence."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import batch
from specgen_addon.cli import app
from specgen_addon.cli.photo_args import apply_keys, check_photo_args, photo_dests, photo_inputs
from specgen_addon.cli.scene_args import parse_apply
from specgen_addon.common.errors import SpecGenError

REPO = Path(__file__).resolve().parents[2]
PHOTO = REPO / "examples" / "sphere.png"
#: infer's options that are about its output file, not the photo.
INFER_ONLY = {"image", "output", "full_table", "range", "rgb", "quiet", "bands", "func", "command"}


def _infer_parser() -> argparse.ArgumentParser:
    sub = next(a for a in app.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["infer"]


def _dests(parser: argparse.ArgumentParser) -> set[str]:
    return {a.dest for a in parser._actions if a.dest != "help"}


def test_infer_and_batch_take_the_same_photo_options():
    infer, ours = _dests(_infer_parser()), _dests(batch.build_parser())
    assert photo_dests() <= infer and photo_dests() <= ours
    # every option infer has about the photo and its generation, batch.py has too
    assert infer - INFER_ONLY - ours == set()
    assert {"light_probe", "white_patch", "colour_checker", "circle_preview", "latent_fit"} <= photo_dests()


def test_every_photo_option_is_an_apply_key():
    actions = {a.dest: a for a in _infer_parser()._actions}
    for dest in photo_dests():
        flag = next(s for s in actions[dest].option_strings if s.startswith("--"))
        assert flag[2:] in apply_keys(), flag


def test_apply_options_read_like_the_command_line():
    argv = ["--light", "30,20,2,3200K", "--light-vector", "0,1,1,0.5,1/0.8/0.6", "--ambient", "0.1",
            "--linear", "--white-level", "0.9", "--circle", "10,20,30", "--mask", "C:/m.png",
            "--white-patch", "1,2,3,4", "--colour-checker", "--no-refine", "--model", "thin-film", "--latent-fit",
            "--light-probe", "chrome.png", "--probe-circle", "5,6,7", "--input-env", "estimate"]
    cli = _infer_parser().parse_args(["photo.png", "-o", "x.npz", *argv])
    spec = parse_apply("D:/photo.png:Cube:light=30,20,2,3200K,light-vector=0,1,1,0.5,1/0.8/0.6,"
                       "ambient=0.1,linear=on,white-level=0.9,circle=10,20,30,mask=C:/m.png,"
                       "white-patch=1,2,3,4,colour-checker=on,refine=off,model=thin-film,latent-fit=on,"
                       "light-probe=chrome.png,probe-circle=5,6,7,env=estimate")
    assert spec.image == Path("D:/photo.png") and spec.object_name == "Cube"
    base = _infer_parser().parse_args(["photo.png", "-o", "x.npz"])
    ns = spec.namespace(base)
    for dest in photo_dests():
        assert getattr(ns, dest) == getattr(cli, dest), dest


def test_a_photos_lights_replace_the_commands():
    base = _infer_parser().parse_args(["p.png", "-o", "x.npz", "--light", "0,0"])
    ns = parse_apply("p.png:Cube:light=10,20,light=30,40").namespace(base)
    assert ns.light == ["10,20", "30,40"] and base.light == ["0,0"]


def _run_infer(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "specgen_addon", "infer", *args], cwd=REPO, check=False,
                          capture_output=True, text=True, timeout=300)


def _black_png(path: Path) -> Path:
    from PIL import Image

    Image.fromarray(np.zeros((64, 64, 3), np.uint8)).save(path)
    return path


def _panorama(path: Path, w: int, h: int) -> Path:
    from specgen_addon.common.image_io import write_exr

    write_exr(path, {c: np.ones((h, w), np.float32) for c in "RGB"})
    return path


@pytest.fixture
def bad_inputs(tmp_path):
    return {"light": (["--light", "2"], "a light needs a direction"),
            "probe": (["--light-probe", str(_black_png(tmp_path / "chrome.png"))], "chrome ball not found"),
            "panorama": (["--input-env", str(_panorama(tmp_path / "room.exr", 30, 20))],
                         "twice as wide as it is high")}


@pytest.mark.parametrize("case", ["light", "probe", "panorama"])
def test_infer_refuses_a_bad_light_in_one_sentence(tmp_path, bad_inputs, case):
    argv, message = bad_inputs[case]
    res = _run_infer(str(PHOTO), "-o", str(tmp_path / "o.npz"), *argv)
    err = res.stderr.strip()
    assert res.returncode == 2 and message in err and err.count("\n") == 0, err
    assert not (tmp_path / "o.npz").exists()


@pytest.mark.parametrize("case", ["light", "probe", "panorama"])
def test_the_checks_batch_runs_first_refuse_the_same(tmp_path, bad_inputs, case):
    argv, message = bad_inputs[case]
    args = batch.build_parser().parse_args(["--image", str(PHOTO), "--out", str(tmp_path), *argv])
    with pytest.raises(SpecGenError, match=message):
        check_photo_args(args, PHOTO)
        photo_inputs(args, PHOTO, tmp_path / "probe.exr")   # the chrome ball is read here


@pytest.mark.parametrize("case", ["light", "probe", "panorama"])
def test_an_apply_photo_refuses_the_same(tmp_path, bad_inputs, case):
    argv, message = bad_inputs[case]
    key, value = argv[0][2:].replace("input-env", "env"), argv[1]
    spec = parse_apply(f"{PHOTO}:Cube:{key}={value}")
    ns = spec.namespace(batch.build_parser().parse_args(["--scene", "--out", str(tmp_path)]))
    with pytest.raises(SpecGenError, match=message):
        check_photo_args(ns, PHOTO)
        photo_inputs(ns, PHOTO, tmp_path / "probe.exr")


def test_estimate_and_a_probe_refuse_lights_given_with_them(tmp_path):
    parser = batch.build_parser()
    for argv in (["--input-env", "estimate", "--light", "10,20"],
                 ["--light-probe", str(PHOTO), "--light", "10,20"]):
        args = parser.parse_args(["--image", str(PHOTO), "--out", str(tmp_path), *argv])
        with pytest.raises(SpecGenError, match="leave out --light"):
            check_photo_args(args, PHOTO)


def test_batch_takes_an_estimated_light_and_a_chrome_ball(tmp_path, capsys):
    parser = batch.build_parser()
    for argv in (["--input-env", "estimate"],
                 ["--light-probe", str(PHOTO), "--probe-circle", "64,64,64", "--white-patch", "50,50,8,8"]):
        args = parser.parse_args(["--image", str(PHOTO), "--out", str(tmp_path), *argv])
        check_photo_args(args, PHOTO)
        source, lighting = photo_inputs(args, PHOTO, tmp_path / "lookup" / "probe.exr")
        assert source.path == PHOTO and not lighting.is_canonical
    out = capsys.readouterr().out
    assert "input lighting estimated from the ball" in out and "unwrapped from the chrome ball" in out
    assert (tmp_path / "lookup" / "probe.exr").is_file()


def test_batch_and_batch_many_take_a_light_from_the_left_written_with_a_space(tmp_path, capsys):
    # the first light parses (azimuth −30°); the second is refused by the light's own check, in one line
    from specgen_addon.scale.batch_many import DEFAULT_BATCH_SCRIPT, check_batch_args

    code = batch.main(["--image", str(PHOTO), "--out", str(tmp_path / "o"), "--light", "-30,20",
                       "--light-vector", "-0,0,0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "a light needs a direction" in err[-1], err
    check_batch_args(Path(DEFAULT_BATCH_SCRIPT), ["--light", "-30,20", "--light-vector", "-0.5,0.5,0.7"])


def test_batch_and_batch_many_take_a_circle_past_the_left_edge_written_with_a_space(tmp_path, capsys):
    # parsed, not taken for an option: the circle's own check refuses it, in one line
    from specgen_addon.scale.batch_many import DEFAULT_BATCH_SCRIPT, check_batch_args

    code = batch.main(["--image", str(PHOTO), "--out", str(tmp_path / "o"), "--circle", "-10,20,30"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "the circle (-10, 20, r 30) does not lie in" in err[-1], err
    check_batch_args(Path(DEFAULT_BATCH_SCRIPT), ["--white-patch", "-5,10,20,20", "--circle", "-10,20,30",
                                                  "--light-probe", str(PHOTO), "--probe-circle", "-1,2,3"])
