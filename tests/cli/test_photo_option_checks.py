"""A photo's options refuse, in one sentence and before any work, a value out of range, an option
that does not apply to the light chosen and a circle preview that is not a PNG of its own:
``infer``, batch.py and each ``--apply`` photo alike. The thin-film model reports its circle too."""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import pytest

import batch
from specgen_addon.cli.app import main
from specgen_addon.cli.photo_args import check_photo_args, print_photo_report
from specgen_addon.cli.scene_args import parse_apply
from specgen_addon.common.errors import SpecGenError
from specgen_addon.generate import pipeline
from specgen_addon.photo.sphere_image import PhotoSource

REPO = Path(__file__).resolve().parents[2]
PHOTO = REPO / "examples" / "sphere.png"

#: Options refused alike by infer and batch.py: (argv, what the one line says).
BAD_OPTIONS = {
    "an absurd light power": (["--light", "27,29,1e300"], "power must be a positive number up to 1,000,000"),
    "an absurd ambient term": (["--light", "27,29", "--ambient", "1e30"],
                               "ambient term must be a non-negative number up to 1,000,000"),
    "a reflectance of 0": (["--light-probe", "{photo}", "--probe-circle", "64,64,64",
                            "--probe-reflectance", "0"], "the chrome ball's reflectance must lie in (0, 1], got 0"),
    "an ambient term with an estimate": (["--input-env", "estimate", "--ambient", "0.5"],
                                         "--input-env estimate finds the light itself: leave out --ambient"),
    "an ambient term with a chrome ball": (["--light-probe", "{photo}", "--ambient", "0.5"],
                                           "--light-probe gives the room's light: leave out --ambient"),
    "a map rotation with no map": (["--input-rotation", "30"],
                                   "--input-rotation applies to an --input-env map"),
    "a map exposure with lights only": (["--light", "30,20", "--input-exposure", "2"],
                                        "--input-exposure applies to an --input-env map"),
    "both with an estimate": (["--input-env", "estimate", "--input-rotation", "30", "--input-exposure", "2"],
                              "leave out --input-rotation and --input-exposure"),
    "a probe mask with no chrome ball": (["--probe-mask", "{photo}"],
                                         "--probe-mask applies to the chrome ball of --light-probe"),
    "a probe circle with no chrome ball": (["--probe-circle", "1,2,3"],
                                           "--probe-circle applies to the chrome ball of --light-probe"),
    "a reflectance with no chrome ball": (["--probe-reflectance", "0.7"],
                                          "--probe-reflectance applies to the chrome ball of --light-probe"),
    "a malformed chrome ball circle": (["--light-probe", "{photo}", "--probe-circle", "64,64"],
                                       "--probe-circle takes X,Y,R in pixels"),
    "a circle and a mask": (["--circle", "64,64,60", "--mask", "{photo}"],
                            "--circle and --mask both place the ball: give one"),
    "a chrome ball circle and mask": (["--light-probe", "{photo}", "--probe-circle", "64,64,64",
                                       "--probe-mask", "{photo}"],
                                      "--probe-circle and --probe-mask both place the ball: give one"),
}

#: Circle previews refused by infer: (argv, what the one line says).
BAD_PREVIEWS = {
    "-o itself": (["--circle-preview", "{tmp}/o.npz"], "--circle-preview {tmp}/o.npz is the same file as -o"),
    "the photo itself": (["--circle-preview", "{photo}", "--overwrite"],
                         "--circle-preview {photo} is the same file as the photo"),
    "the chrome ball photo": (["--light-probe", "{photo}", "--circle-preview", "{photo}", "--overwrite"],
                              "is the same file as the photo"),
    "in a missing folder": (["--circle-preview", "{tmp}/nope/c.png"],
                            "output folder {tmp}/nope does not exist"),
    "a folder": (["--circle-preview", "{tmp}"], "{tmp}: is a folder"),
    "not a .png": (["--circle-preview", "{tmp}/c.jpg"],
                   "--circle-preview writes a PNG, so its name must end in .png"),
}


def _filled(argv: list[str], tmp_path: Path) -> list[str]:
    return [a.format(photo=PHOTO, tmp=tmp_path) for a in argv]


def _one_error_line(code: int, capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("case", sorted(BAD_OPTIONS))
def test_infer_refuses_a_bad_or_needless_photo_option_in_one_line(tmp_path, capsys, case):
    argv, message = BAD_OPTIONS[case]
    code = main(["infer", str(PHOTO), "-o", str(tmp_path / "o.npz"), "--quiet", *_filled(argv, tmp_path)])
    assert message in _one_error_line(code, capsys)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("case", sorted(BAD_OPTIONS))
def test_batch_refuses_a_bad_or_needless_photo_option_in_one_line(tmp_path, capsys, case):
    argv, message = BAD_OPTIONS[case]
    code = batch.main(["--image", str(PHOTO), "--out", str(tmp_path / "out"), *_filled(argv, tmp_path)])
    assert message in _one_error_line(code, capsys)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", sorted(BAD_OPTIONS))
def test_an_apply_photo_refuses_a_bad_or_needless_photo_option(tmp_path, case):
    argv, message = BAD_OPTIONS[case]
    argv = _filled(argv, tmp_path)
    options = ",".join(f"{flag[2:]}={value}" for flag, value in zip(argv[::2], argv[1::2]))
    spec = parse_apply(f"{PHOTO}:Cube:{options}")
    ns = spec.namespace(batch.build_parser().parse_args(["--scene", "--out", str(tmp_path / "out")]))
    with pytest.raises(SpecGenError) as err:
        check_photo_args(ns, PHOTO)
    assert message in str(err.value)


@pytest.mark.parametrize("case", sorted(BAD_PREVIEWS))
def test_infer_refuses_a_circle_preview_that_is_not_a_new_png_of_its_own(tmp_path, capsys, case):
    argv, message = BAD_PREVIEWS[case]
    before = PHOTO.read_bytes()
    code = main(["infer", str(PHOTO), "-o", str(tmp_path / "o.npz"), "--quiet", *_filled(argv, tmp_path)])
    assert message.format(photo=PHOTO, tmp=tmp_path) in _one_error_line(code, capsys)
    assert list(tmp_path.iterdir()) == [] and PHOTO.read_bytes() == before


@pytest.mark.parametrize("preview,message", [
    ("{tmp}/out/sphere_sphere_studio_preview.png", "is the same file as the render's preview"),
    ("{tmp}/out/sphere_sphere_studio.exr", "is the same file as the render"),
    ("{tmp}/nope/c.png", "output folder {tmp}/nope does not exist"),
    ("{tmp}", "{tmp}: is a folder"),
    ("{tmp}/c.jpg", "--circle-preview writes a PNG, so its name must end in .png"),
])
def test_batch_refuses_a_circle_preview_that_is_not_a_new_png_of_its_own(tmp_path, capsys, preview, message):
    code = batch.main(["--image", str(PHOTO), "--out", str(tmp_path / "out"),
                       "--circle-preview", preview.format(tmp=tmp_path)])
    assert message.format(tmp=tmp_path) in _one_error_line(code, capsys)
    assert not (tmp_path / "out").exists()


def test_batch_takes_a_circle_preview_in_the_output_folder_it_is_about_to_make(tmp_path):
    out = tmp_path / "out"
    args = batch.build_parser().parse_args(["--image", str(PHOTO), "--out", str(out),
                                            "--circle-preview", str(out / "circle.png")])
    check_photo_args(args, PHOTO, {}, out_dir=out)
    with pytest.raises(SpecGenError, match="does not exist"):   # the folder the run makes, and no other
        check_photo_args(args, PHOTO, {}, out_dir=tmp_path / "elsewhere")


def test_two_apply_photos_may_not_write_one_circle_preview(tmp_path):
    args = batch.build_parser().parse_args(["--scene", "--out", str(tmp_path / "out"),
                                            "--circle-preview", str(tmp_path / "c.png")])
    applies = [parse_apply(f"{PHOTO}:Cube"), parse_apply(f"{PHOTO}:Suzanne")]
    with pytest.raises(SpecGenError, match=r"c\.png is the same file as sphere\.png's circle preview"):
        batch._check_photos(applies, args)
    applies[1] = parse_apply(f"{PHOTO}:Suzanne:circle-preview={tmp_path / 'd.png'}")
    assert len(batch._check_photos(applies, args)) == 2


class _StandInFilmFit:
    """What the thin-film fit returns, without the fit (about 25 s): its table and its report."""

    warnings = ()

    def table(self, wavelengths, progress=None, cancel=None):
        return SimpleNamespace(metadata={})


def test_the_thin_film_model_reports_its_circle_and_writes_its_preview(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(pipeline, "fit_thin_film", lambda *args, **kwargs: _StandInFilmFit())
    source = PhotoSource(PHOTO)
    generated = pipeline.generate(source, model="thin-film")
    preview = tmp_path / "circle.png"
    print_photo_report(generated, argparse.Namespace(circle_preview=preview, overwrite=False), source)
    out = capsys.readouterr().out
    assert "sphere: centre (64.00, 64.00) px, radius 64.00 px" in out
    assert preview.is_file() and f"wrote {preview}" in out


def test_no_key_light_is_refused_for_the_canonical_studio_which_always_has_it(tmp_path, capsys):
    code = main(["infer", str(PHOTO), "-o", str(tmp_path / "o.npz"), "--quiet", "--no-input-key-light"])
    assert "--no-input-key-light applies to an --input-env map" in _one_error_line(code, capsys)
    code = main(["infer", str(PHOTO), "-o", str(tmp_path / "o.npz"), "--quiet", "--no-input-key-light",
                 "--input-env", "forest", "--probe-reflectance", "0.5"])
    assert "--probe-reflectance applies" in _one_error_line(code, capsys)   # with a map: taken
