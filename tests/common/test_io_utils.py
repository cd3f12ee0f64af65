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
