"""Native chatter kept off stdout (common/quiet.py): what C libraries and Python print in the block
is silenced; the job's own lines, said through the block's ``say``, still reach stdout."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import os
from specgen_addon.common.quiet import native_stdout_silenced
with native_stdout_silenced(True) as say:
    os.write(1, b"Saved: pass0.exr\\n")       # as Cycles writes it, past Python's sys.stdout
    print("python chatter")
    say("band 1 of 4 rendered")
with native_stdout_silenced(False) as say:
    say("not silenced: said as a print")
print("after")
"""


def test_the_block_silences_native_and_python_output_but_not_what_it_says():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True,
                         timeout=60).stdout
    assert out.splitlines() == ["band 1 of 4 rendered", "not silenced: said as a print", "after"]
