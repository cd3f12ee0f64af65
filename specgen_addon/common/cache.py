"""Where the evaluation keeps derived artefacts that are costly to rebuild (never committed).

``SPECGEN_CACHE_DIR`` overrides the location; the default is ``<repo>/.cache/specgen`` (gitignored)
when the package sits in a writable checkout, else ``~/.cache/specgen``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from specgen_addon.common.atomic_io import atomic_write


def cache_root() -> Path:
    """The cache directory (created on demand)."""
    env = os.environ.get("SPECGEN_CACHE_DIR")
    if env:
        root = Path(env)
    else:
        repo = Path(__file__).resolve().parents[2]
        root = repo / ".cache" / "specgen" if os.access(repo, os.W_OK) else Path.home() / ".cache" / "specgen"
    root.mkdir(parents=True, exist_ok=True)
    return root


def read_json(path: Path) -> Any | None:
    """The JSON content of ``path``, or None when it is absent or unreadable (a stale partial)."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as JSON atomically (a crash never leaves a half-written cache entry)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, overwrite=True) as tmp:
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
