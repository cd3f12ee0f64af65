"""A stop that lands between a staging file's creation and its ledger entry still removes it."""

from __future__ import annotations

import os

from specgen_addon.common import atomic_io


def test_a_staging_file_created_but_not_yet_in_the_ledger_is_removed_by_the_clean_up(tmp_path):
    mark = atomic_io.ledger_mark()
    target = tmp_path / "out.npz"
    tmp = tmp_path / atomic_io._temp_name(target)
    key = os.path.abspath(tmp)
    # the state atomic_write is in right after os.open, before record_created
    atomic_io._STAGING[key] = os.path.abspath(target)
    atomic_io._PENDING[key] = next(atomic_io._SEQ)
    try:
        tmp.write_bytes(b"")
        other = tmp_path / "theirs.txt"        # not ours: never removed
        other.write_text("x")
        found = atomic_io.created_since(mark, under=[target])
        assert found == [tmp]
        assert atomic_io.remove_created(found) == [tmp]
        assert not tmp.exists() and other.exists()
    finally:
        atomic_io._STAGING.pop(key, None)
        atomic_io._PENDING.pop(key, None)


def test_a_pending_name_that_was_never_created_is_not_reported(tmp_path):
    mark = atomic_io.ledger_mark()
    target = tmp_path / "out.npz"
    key = os.path.abspath(tmp_path / atomic_io._temp_name(target))
    atomic_io._STAGING[key] = os.path.abspath(target)
    atomic_io._PENDING[key] = next(atomic_io._SEQ)
    try:
        assert atomic_io.created_since(mark, under=[target]) == []
    finally:
        atomic_io._STAGING.pop(key, None)
        atomic_io._PENDING.pop(key, None)
