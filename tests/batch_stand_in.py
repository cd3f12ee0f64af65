"""Stand-ins for batch.py that batch-many runs in the tests: same options, a body of the test's
choosing, and input files to feed them.

Import it by name (``from batch_stand_in import stand_in, touch_inputs``): tests/ is on the test path.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

#: batch.py's options as batch-many passes them; the body runs with ``a`` (the parsed options)
#: and ``src`` (the input file) set, and the modules ``os``, ``pathlib``, ``sys``, ``time``.
HEAD = '''
import argparse, os, pathlib, sys, time
def build_parser():
    ap = argparse.ArgumentParser()
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--image"); g.add_argument("--brdf")
    ap.add_argument("--out", required=True); ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--samples", type=int, default=1)
    return ap
if __name__ == "__main__":
    a = build_parser().parse_args()
    src = pathlib.Path(a.image or a.brdf)
'''


def stand_in_source(body: str) -> str:
    """The stand-in's Python source: :data:`HEAD` followed by ``body`` (dedented)."""
    return HEAD + textwrap.indent(textwrap.dedent(body).strip("\n"), "    ") + "\n"


def stand_in(path: Path, body: str) -> Path:
    """Write the stand-in with ``body`` to ``path``; gives ``path``."""
    path.write_text(stand_in_source(body))
    return path


def touch_inputs(folder: Path, *names: str) -> list[Path]:
    """Create one-byte input files ``names`` in ``folder`` (made if missing); gives their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    for n in names:
        (folder / n).write_bytes(b"x")
    return [folder / n for n in names]
