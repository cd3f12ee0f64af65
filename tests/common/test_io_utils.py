import os
import stat

import pytest

from specgen_addon.common.errors import OutputExistsError, SpecGenError
from specgen_addon.common.atomic_io import atomic_write


def test_failed_write_leaves_nothing_behind(tmp_path):
    with pytest.raises(RuntimeError):
        with atomic_write(tmp_path / "out.exr") as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_success_renames_with_ordinary_permissions(tmp_path):
    with atomic_write(tmp_path / "out.txt") as tmp:
        assert tmp.suffix == ".txt" and tmp.parent == tmp_path
        tmp.write_text("done")
    out = tmp_path / "out.txt"
    assert out.read_text() == "done"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~mask


def test_existing_output_is_kept_unless_overwrite(tmp_path):
    out = tmp_path / "out.txt"
    out.write_text("old")
    with pytest.raises(OutputExistsError):
        with atomic_write(out):
            pass
    with atomic_write(out, overwrite=True) as tmp:
        tmp.write_text("new")
    assert out.read_text() == "new"


def test_missing_directory_is_a_clear_error(tmp_path):
    with pytest.raises(SpecGenError, match="does not exist"):
        with atomic_write(tmp_path / "nope" / "out.txt"):
            pass


def test_a_link_to_a_missing_file_at_the_output_is_refused_before_the_work(tmp_path, repo_dir):
    """A dangling link is an existing output: refused up front (it was found only when the
    finished file could not be published), and replaced, link and all, with overwrite."""
    import subprocess
    import sys

    from specgen_addon.common.limits import check_output_file

    out = tmp_path / "b.npz"
    out.symlink_to(tmp_path / "elsewhere.npz")
    with pytest.raises(OutputExistsError, match="a link to a missing file"):
        check_output_file(out)
    assert check_output_file(out, overwrite=True) == out
    done = subprocess.run([sys.executable, "-m", "specgen_addon", "infer", "examples/sphere.png", "-o",
                           str(out), "--no-refine"], capture_output=True, text=True, timeout=120,
                          cwd=repo_dir)
    assert done.returncode != 0 and "a link to a missing file" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "elsewhere.npz").exists()
    render = tmp_path / "sphere_sphere_studio.exr"                     # batch.py's render, likewise
    render.symlink_to(tmp_path / "elsewhere.exr")
    done = subprocess.run([sys.executable, "batch.py", "--image", "examples/sphere.png", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=120, cwd=repo_dir)
    assert done.returncode == 2 and "a link to a missing file" in done.stderr, done.stderr
    assert "baked in" not in done.stdout, done.stdout                  # refused before the work


def _write(path, text, overwrite=True):
    with atomic_write(path, overwrite=overwrite) as tmp:
        tmp.write_text(text)


@pytest.mark.parametrize("stop", [KeyboardInterrupt, SpecGenError], ids=["stopped", "failed"])
def test_an_overwrite_cut_short_puts_back_every_file_it_had_replaced(tmp_path, capsys, stop):
    """``--overwrite`` replaces an earlier run's pair of outputs one by one; stopped or failed
    after the first, the command leaves both old files, not a new one beside an old one."""
    from specgen_addon.cli.app import run_guarded

    first, second = tmp_path / "b.npz", tmp_path / "b_probe.exr"
    first.write_text("old material")
    second.write_text("old probe")

    def work():
        _write(second, "new probe")          # published, then the run is cut short
        raise stop("stopped meanwhile")

    assert run_guarded("infer", work, ([], [first, second])) != 0
    assert second.read_text() == "old probe" and first.read_text() == "old material"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.npz", "b_probe.exr"]   # no copies left
    capsys.readouterr()


def test_an_overwrite_that_succeeds_keeps_the_new_files_and_drops_the_old_copies(tmp_path):
    from specgen_addon.cli.app import run_guarded

    out = tmp_path / "b.npz"
    out.write_text("old")
    assert run_guarded("infer", lambda: _write(out, "new"), ([], [out])) == 0
    assert out.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["b.npz"]
    _write(out, "outside a command")        # no command keeping copies: replaced at once, none made
    assert out.read_text() == "outside a command" and [p.name for p in tmp_path.iterdir()] == ["b.npz"]


def test_an_output_under_a_file_names_the_file_in_the_way(tmp_path):
    from specgen_addon.common.limits import check_output_file

    (tmp_path / "FILE").write_text("a file, not a folder")
    with pytest.raises(SpecGenError, match=r"cannot be the output folder \(.*FILE is a file\)"):
        check_output_file(tmp_path / "FILE" / "sub" / "b.npz")
    with pytest.raises(SpecGenError, match="output folder .*missing does not exist"):
        check_output_file(tmp_path / "missing" / "b.npz")
