"""batch-many's command line: the photo options in --batch-args refused up front as batch.py
refuses them, no option that writes a file outside the item folders, and every photo file the
photo reader takes (TGA, HDR, camera RAW) accepted as an input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.photo.read import FLOAT_SUFFIXES, RAW_SUFFIXES
from specgen_addon.scale import items as items_mod
from specgen_addon.scale.batch_many import DEFAULT_BATCH_SCRIPT, check_batch_args
from batch_stand_in import touch_inputs

REPO = Path(__file__).resolve().parents[2]
PHOTO = REPO / "examples" / "sphere.png"


def _batch_many(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "specgen_addon", "batch-many", str(PHOTO),
                           "--out", str(tmp_path / "out"), "--quiet", *args],
                          capture_output=True, text=True, cwd=REPO, timeout=120)


BAD_PHOTO_OPTIONS = {
    "light without elevation": ("--mesh sphere --light 30", "a light needs a direction"),
    "circle of two numbers": ("--circle 1,2", "--circle takes X,Y,R"),
    "estimate with a light": ("--input-env estimate --light 30,20", "leave out --light"),
    "unknown map": ("--input-env nowhere", "no bundled map named 'nowhere'"),
    "probe file missing": ("--light-probe missing_chrome.png", "missing_chrome.png"),
    "white level zero": ("--white-level 0", "the white level must be a positive number"),
}


@pytest.mark.parametrize("case", sorted(BAD_PHOTO_OPTIONS))
def test_a_bad_photo_option_in_batch_args_is_refused_before_any_item_runs(case):
    argv, message = BAD_PHOTO_OPTIONS[case]
    with pytest.raises(SpecGenError, match=message):
        check_batch_args(DEFAULT_BATCH_SCRIPT, argv.split())


def test_good_photo_options_in_batch_args_pass_the_up_front_check():
    check_batch_args(DEFAULT_BATCH_SCRIPT, ["--light", "27,29", "--linear", "--ambient", "0.05",
                                            "--circle", "64,64,60", "--white-patch", "1,1,4,4",
                                            "--light", "-30,20,2,3200K"])
    check_batch_args(DEFAULT_BATCH_SCRIPT, ["--input-env", "estimate", "--no-refine"])


def test_batch_many_with_a_bad_light_exits_2_in_one_line_and_writes_nothing(tmp_path):
    res = _batch_many(tmp_path, "--batch-args=--mesh sphere --light 30")
    err = res.stderr.strip()
    assert res.returncode == 2 and "a light needs a direction" in err and err.count("\n") == 0, err
    assert "Dask" not in res.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == []   # no OUT, no report.json, no failed/


@pytest.mark.parametrize("option", ["--circle-preview {keep}", "--circle-preview={keep}",
                                    "--circle-prev {keep}", "--circle-preview relative.png"])
def test_a_circle_preview_in_batch_args_is_refused_and_no_file_outside_out_is_touched(tmp_path, option):
    keep = tmp_path / "keep.png"
    keep.write_bytes(b"mine")
    res = _batch_many(tmp_path, f"--batch-args={option.format(keep=keep)}")
    err = res.stderr.strip()
    assert res.returncode == 2 and "--circle-preview names one file outside the item folders" in err, err
    assert err.count("\n") == 0
    assert keep.read_bytes() == b"mine" and sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]
    assert not (REPO / "relative.png").exists()


def test_tga_hdr_and_camera_raw_files_are_photos_as_the_photo_reader_takes_them(tmp_path):
    names = ["gray.0.tga", "room.hdr", "shot.dng", "shot2.CR2", "shot3.nef", "oak.png", "felt.bsdf"]
    files = items_mod.collect_inputs(touch_inputs(tmp_path / "in", *names))   # each named on its own
    assert [f.name for f in files] == names
    kinds = {Path(it.input).name: it.kind for it in items_mod.make_items(files)}
    assert kinds == {**{n: "image" for n in names}, "felt.bsdf": "brdf"}
    assert [f.name for f in items_mod.collect_inputs([tmp_path / "in"])] == sorted(names)   # a folder too
    assert set(RAW_SUFFIXES) | set(FLOAT_SUFFIXES) <= set(items_mod.IMAGE_SUFFIXES)
    with pytest.raises(SpecGenError, match=r"notes\.txt: not a known input .*\.tga.*\.hdr.*\.dng"):
        items_mod.collect_inputs(touch_inputs(tmp_path / "in", "notes.txt"))


#: Arguments refused before any work, in one sentence: (argv, what the one line says).
BAD_ARGUMENTS = {
    "a binary manifest": (["--manifest", "{tmp}/list.txt"], "list.txt: not a text manifest"),
    "a folder as the manifest": (["--manifest", "{tmp}/in"], "in: is a folder, expected a manifest file"),
    "a dashboard address with no port": (["{photo}", "--dashboard-address", "nonsense"],
                                         "--dashboard-address nonsense: expected HOST:PORT or :PORT"),
    "a dashboard port above 65535": (["{photo}", "--dashboard-address", "127.0.0.1:99999"],
                                     "the port must be between 0 and 65535"),
    "a negative dashboard port": (["{photo}", "--dashboard-address", ":-5"], "the port must be between 0 and 65535"),
    "a dashboard host of another machine": (["{photo}", "--dashboard-address", "192.0.2.1:8787"],
                                            "192.0.2.1 is not an address of this machine"),
    "a Blender that is not executable": (["{photo}", "--blender", "{tmp}/blender"],
                                         "blender: not an executable file"),
    "a folder as Blender": (["{photo}", "--blender", "{tmp}/in"], "is a folder, expected the Blender executable"),
    "a Blender not on PATH": (["{photo}", "--blender", "no-such-blender-7"], "no such program on PATH"),
}


@pytest.mark.parametrize("case", sorted(BAD_ARGUMENTS))
def test_an_unusable_argument_is_refused_in_one_sentence_before_any_work(case, tmp_path, capsys):
    from specgen_addon.cli.app import main

    touch_inputs(tmp_path / "in", "oak.png")
    (tmp_path / "list.txt").write_bytes(bytes(range(256)) * 4)   # not text
    (tmp_path / "blender").write_text("#!/bin/sh\n")              # not executable
    before = sorted(p.name for p in tmp_path.iterdir())
    argv, message = BAD_ARGUMENTS[case]
    argv = [a.format(tmp=tmp_path, photo=PHOTO) for a in argv]
    code = main(["batch-many", *argv, "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and message in err, err
    assert "internal error" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # no OUT, no lock left


def test_dashboard_addresses_dask_takes_pass_the_up_front_check():
    from specgen_addon.scale.batch_many import check_dashboard_address

    for address in (":0", ":8787", "8787", "127.0.0.1:8787", "localhost:0", "0.0.0.0:65535"):
        check_dashboard_address(address)
    check_dashboard_address("192.0.2.1:8787", local=False)   # with --scheduler it is not used here
