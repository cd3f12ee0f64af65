"""`--colour-checker` on the command line, in batch.py and as an `--apply` photo's key: the photo is
balanced from the chart and the run reports the chart and the gains; a photo without a chart is one
sentence and exit 2, and so is the option given with `--white-patch`, before anything is written."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from checker_photo import CIRCLE, checker_photo, needs_detector

import batch
from specgen_addon.cli.photo_args import check_photo_args, photo_inputs, print_photo_report
from specgen_addon.cli.scene_args import parse_apply
from specgen_addon.common.errors import SpecGenError

REPO = Path(__file__).resolve().parents[2]
CAST = np.array([1.3, 1.0, 0.6])
CIRCLE_ARG = ",".join(f"{v:g}" for v in CIRCLE)


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    root = tmp_path_factory.mktemp("checker_cli")
    return {"cast": checker_photo(root / "cast.exr", cast=CAST, repo=REPO),
            "none": checker_photo(root / "none.exr", repo=REPO, chart=False)}


def _run_infer(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "specgen_addon", "infer", *args], cwd=REPO, check=False,
                          capture_output=True, text=True, timeout=300)


@needs_detector
@pytest.mark.slow
def test_infer_without_a_chart_in_the_photo_is_one_sentence_and_exit_2(tmp_path, photos):
    res = _run_infer(str(photos["none"]), "-o", str(tmp_path / "o.npz"), "--circle", CIRCLE_ARG,
                     "--colour-checker")
    err = res.stderr.strip().splitlines()[-1]
    assert res.returncode == 2 and "no colour checker found in the photo" in err, res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "o.npz").exists()
    said = [line for line in res.stderr.splitlines() if line.strip() and not line.startswith("infer:")]
    assert said == [err], res.stderr          # the detector's own import notes are not repeated


def test_infer_refuses_a_chart_and_a_white_patch_together(tmp_path, photos):
    res = _run_infer(str(photos["cast"]), "-o", str(tmp_path / "o.npz"), "--circle", CIRCLE_ARG,
                     "--colour-checker", "--white-patch", "1,1,4,4")
    err = res.stderr.strip().splitlines()[-1]
    assert res.returncode == 2 and err == "error: --white-patch and --colour-checker both set the white balance: give one"
    assert not (tmp_path / "o.npz").exists()


@needs_detector
@pytest.mark.slow
def test_batch_balances_from_the_chart_and_reports_it(tmp_path, photos, capsys):
    photo = photos["cast"]
    args = batch.build_parser().parse_args(["--image", str(photo), "--out", str(tmp_path), "--circle",
                                            CIRCLE_ARG, "--colour-checker", "--light", "0,0,1,D65"])
    check_photo_args(args, photo)
    source, _ = photo_inputs(args, photo, tmp_path / "probe.exr")
    crop = source.crop()
    gains = crop.white_gains * CAST
    np.testing.assert_allclose(gains / gains[1], 1.0, rtol=1e-3)    # a D65 light: the greys neutral
    print_photo_report(SimpleNamespace(crop=crop, network_reproduction=None), args, source)
    out = capsys.readouterr().out.splitlines()
    assert any("white balance from the colour checker: gains R" in line for line in out), out
    assert any(line.startswith("colour checker: a ColorChecker Classic at") and "24 swatches sampled" in line
               for line in out), out


def test_an_apply_photo_takes_the_chart_and_refuses_it_with_a_white_patch(tmp_path, photos):
    base = batch.build_parser().parse_args(["--scene", "--out", str(tmp_path)])
    ns = parse_apply(f"{photos['cast']}:Cube:colour-checker=on").namespace(base)
    assert ns.colour_checker is True and base.colour_checker is False
    both = parse_apply(f"{photos['cast']}:Cube:colour-checker=on,white-patch=1,1,4,4").namespace(base)
    with pytest.raises(SpecGenError, match="both set the white balance"):
        check_photo_args(both, photos["cast"])
