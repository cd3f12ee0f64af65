"""Signal handling of :mod:`specgen_addon.common.interrupts`: forked workers, imports, Blender's own code
and C calls, and the watcher's hard stop."""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time

import pytest

from specgen_addon.common.interrupts import HARD_STOP_GRACE_S, stop_on_signals
from stop_stand_ins import fake_blender_modules, sigint_when_ready

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="fork and POSIX signals")


def _sleep_quietly() -> None:
    time.sleep(30)


def test_a_worker_forked_inside_a_stop_block_ends_quietly_on_sigterm():
    """Pool.terminate() sends SIGTERM to the render workers: they must die by the default action,
    not raise the parent's Interrupted (a traceback per worker at the end of every corpus run)."""
    ctx = multiprocessing.get_context("fork")
    with stop_on_signals():
        child = ctx.Process(target=_sleep_quietly)
        child.start()
        time.sleep(0.3)
        os.kill(child.pid, signal.SIGTERM)
        child.join(10)
    assert child.exitcode == -signal.SIGTERM


def test_a_signal_to_a_just_forked_child_does_not_reach_the_parent():
    """SIGTERM sent the moment the child exists, before its at-fork hook ran: it must not come
    through the parent's inherited wakeup pipe (the parent's watcher would end the parent, 143)."""
    ctx = multiprocessing.get_context("fork")
    with stop_on_signals():
        child = ctx.Process(target=_sleep_quietly)
        child.start()
        child.terminate()
        child.join(2)
        if child.is_alive():      # the signal may be lost in the child's fork window
            child.kill()
            child.join(10)
        time.sleep(HARD_STOP_GRACE_S + 0.5)  # the parent's watcher would have acted by now
        assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, signal.SIG_IGN, None)


SLOW_IMPORT_SCRIPT = r"""
import sys, time
sys.path.insert(0, {repo!r})
sys.path.insert(0, {mods!r})
from specgen_addon.common.interrupts import Interrupted, stop_on_signals
try:
    with stop_on_signals():
        print("READY", flush=True)
        import slow_to_import   # the signal lands here (an import: deferred)
        print("IMPORTED", flush=True)
        t = time.monotonic()
        while time.monotonic() - t < 20:   # ordinary code, where it must be raised
            pass
    print("NOT STOPPED", flush=True)
except Interrupted as exc:
    print("RAISED", exc.signal_name, flush=True)
    sys.exit(exc.exit_code)
"""


def test_a_signal_inside_a_slow_import_is_raised_in_the_code_after_it(tmp_path):
    """A lazy ``import onnxruntime`` can take seconds; a Ctrl-C landing there must not end in the
    watcher's hard stop (generic message) but raise in the command's own code once it is over."""
    from pathlib import Path

    mods = tmp_path / "mods"
    mods.mkdir()
    (mods / "slow_to_import.py").write_text(f"import time\ntime.sleep({HARD_STOP_GRACE_S + 2.0})\n")
    script = tmp_path / "s.py"
    script.write_text(SLOW_IMPORT_SCRIPT.format(repo=str(Path(__file__).resolve().parents[2]), mods=str(mods)))
    code, out = sigint_when_ready([sys.executable, str(script)], delay=0.5, timeout=30)  # in the import's sleep
    assert code == 130, out
    assert "IMPORTED" in out and "RAISED SIGINT" in out, out
    assert "cancelled: stopped by" not in out, out


#: A hard-stop clean-up step that takes a second (a large temporary folder), run before the
#: output folder's own clean-up: the main thread comes back from its C call meanwhile.
SLOW_CLEAN_UP = "from specgen_addon.common import interrupts; interrupts._cleanups.append(lambda: time.sleep(1.0))"

GUARDED_SCRIPT = r"""
import sys, time
from pathlib import Path
sys.path.insert(0, {repo!r})
sys.path.insert(0, {blender!r})
import fake_blender
from specgen_addon.cli import app as cli

out = Path({out!r})

from specgen_addon.common.atomic_io import atomic_write, make_dirs

def write(path):
    with atomic_write(path, overwrite=True) as tmp:
        tmp.write_text("x")

def work():
    make_dirs(out / "lookup")
    write(out / "lookup" / "table.json")   # written before the stop, by our code
    {before}
    print("READY", flush=True)
    {call}
    print("BACK IN OUR CODE", flush=True)
    t = time.monotonic()
    while time.monotonic() - t < 20:
        write(out / "lookup" / "ours.txt")
    return 0

sys.exit(cli.run_guarded("the work", work, ([out], []), prog="s"))
"""


def _run_guarded_script(tmp_path, call: str, delay: float, before: str = ""):
    """Start GUARDED_SCRIPT with ``call`` as the step the signal lands in; SIGINT after ``delay``."""
    from pathlib import Path

    blender = fake_blender_modules(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    script = tmp_path / "s.py"
    script.write_text(GUARDED_SCRIPT.format(repo=str(Path(__file__).resolve().parents[2]),
                                            blender=str(blender), out=str(out), call=call,
                                            before=before))
    t0 = time.monotonic()
    code, text = sigint_when_ready([sys.executable, str(script)], delay)
    left = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    return code, text, left, time.monotonic() - t0


def test_a_signal_inside_blender_code_that_keeps_running_is_acted_on_once_in_our_code(tmp_path):
    """A past CI failure: a signal landing in Blender's own Python (bpy's
    start-up, read_factory_settings) was deferred, and the watcher's hard stop cleaned the output
    folder while the main thread went on writing and then raised the same stop itself. Files were
    left behind. Now the watcher waits while the main thread runs, and the stop is acted on once."""
    code, text, left, _ = _run_guarded_script(
        tmp_path, "fake_blender.busy_writing(out / 'lookup', 3.0)", delay=0.3)
    assert code == 130, text
    assert left == ["keep.txt"], (left[:5], text)
    assert text.count("cancelled:") == 1, text
    assert "cancelled: the work stopped by SIGINT; nothing partial was left" in text, text
    assert "BACK IN OUR CODE" in text, text   # the stop was raised in our code, not a hard stop


def test_a_signal_during_a_long_c_call_under_blender_code_stops_within_seconds(tmp_path):
    """A Cycles render keeps the main thread in one C call: the watcher stops the process itself,
    removing what the work wrote, within a few seconds (not after the call)."""
    code, text, left, seconds = _run_guarded_script(
        tmp_path, "fake_blender.stuck_in_a_c_call(30.0)", delay=0.3)
    assert code == 130, text
    assert left == ["keep.txt"], (left, text)
    assert text.count("cancelled:") == 1 and "nothing partial was left" in text, text
    assert "BACK IN OUR CODE" not in text
    assert seconds < 10, seconds


def test_a_signal_handler_frame_is_looked_through_to_the_import_it_interrupted():
    """A second signal (one the watcher delivers again) can land while the first one's handler
    runs: the frame it interrupts is the handler's own, in our code. Raising there, inside an
    import, crashed bpy's start-up (exit -11); the handler's frames must be looked through."""
    from specgen_addon.common import interrupts

    in_handler = compile("import sys\ndef handler_frame():\n    return sys._getframe()\n",
                         interrupts._THIS_FILE, "exec")
    scope: dict = {}
    exec(in_handler, scope)
    in_import = compile("frame = handler_frame()\n", "<frozen importlib._bootstrap>", "exec")
    exec(in_import, scope)
    assert scope["frame"].f_code.co_filename == interrupts._THIS_FILE
    assert interrupts._deferral_reason(scope["frame"]) == "import"


def test_a_hard_stop_parks_the_main_thread_that_comes_back_while_it_cleans_up(tmp_path):
    """The main thread sits in a C call under Blender's code (loading the factory start-up file)
    just longer than the watcher waits, then comes back while the watcher is still cleaning up,
    and would go on writing into the output folder. It is parked at its first Python instruction,
    so nothing it would write is left behind, and the stop is reported once."""
    code, text, left, _ = _run_guarded_script(
        tmp_path, "fake_blender.stuck_in_a_c_call(1.8)", delay=0.3, before=SLOW_CLEAN_UP)
    assert code == 130, text
    assert "BACK IN OUR CODE" not in text, text
    assert left == ["keep.txt"], (left[:5], len(left), text)
    assert text.count("cancelled:") == 1 and "nothing partial was left" in text, text


def test_an_error_that_follows_a_signal_is_reported_as_the_stop(tmp_path):
    """The signal interrupts a system call in Blender's C code, which then fails with its own error:
    the user asked to stop, so the command ends as stopped (130, its one line), not as an internal
    error (2)."""
    code, text, left, _ = _run_guarded_script(tmp_path, "fake_blender.fails_after(1.0)", delay=0.3)
    assert code == 130, text
    assert left == ["keep.txt"], (left, text)
    assert text.count("cancelled:") == 1 and "internal error" not in text, text


def test_a_ctrl_c_while_the_commands_load_is_one_line_and_exit_130(monkeypatch, capsys):
    """The imports take a second or more before a command's clean stop is in place: a Ctrl-C
    then ends the program as one during the work does, without a traceback."""
    import builtins

    from specgen_addon.cli import entry

    real_import = builtins.__import__

    def interrupted(name, *args, **kwargs):
        if name == "specgen_addon.cli.app":
            raise KeyboardInterrupt
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", interrupted)
    assert entry.main() == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cancelled: specgen stopped by SIGINT while starting"), err


def test_a_hard_stop_removes_blenders_session_folder_and_nothing_else(tmp_path, monkeypatch):
    """Blender removes its ``blender_XXXXXX`` session folder only on a normal exit; the hard stop
    ends the process with ``os._exit``, so it removes the folder itself, and only that folder."""
    import tempfile
    from types import SimpleNamespace

    from specgen_addon.common import interrupts

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    session = tmp_path / "blender_a1b2c3"
    (session / "sub").mkdir(parents=True)
    monkeypatch.setitem(sys.modules, "bpy", SimpleNamespace(app=SimpleNamespace(tempdir=str(session) + os.sep)))
    interrupts._remove_blender_session_folder()
    assert not session.exists()
    elsewhere = tmp_path / "project" / "blender_keep"
    elsewhere.mkdir(parents=True)
    monkeypatch.setitem(sys.modules, "bpy", SimpleNamespace(app=SimpleNamespace(tempdir=str(elsewhere))))
    interrupts._remove_blender_session_folder()            # not in the temporary folder: kept
    assert elsewhere.is_dir()
