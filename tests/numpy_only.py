"""A Python child process that can import numpy and the standard library but not the CLI's extra
packages (torch, scipy, scikit-image, Pillow, colour-science, OpenEXR, numba): the panel's path in a
stock Blender, which has numpy and its own bundled modules and nothing else."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

BLOCKED = ("torch", "scipy", "skimage", "PIL", "colour", "OpenEXR", "numba", "llvmlite")


def run_numpy_only(repo_dir: Path, body: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``body`` (dedented Python) with :data:`BLOCKED` unimportable and the repo on the path."""
    prelude = textwrap.dedent(f"""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in {BLOCKED!r}:
                    raise ImportError('blocked: ' + name)
        sys.meta_path.insert(0, Block())
        sys.path.insert(0, {str(repo_dir)!r})
    """)
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(body)], capture_output=True,
                          text=True, timeout=timeout)
