"""SHA-256 sums of the shipped networks: a damaged weights file or ONNX graph is refused on load.

A folder of networks may hold ``SHA256SUMS`` (the ``sha256sum`` format: ``<hex>  <name>`` per
line); the shipped ``weights/`` folder does. Every file listed there is hashed when it is loaded
(:func:`verify`) and refused with :class:`DamagedWeightsError` when the sum differs: flipped
bytes in a ``.pt`` would otherwise load and silently change the output, and a truncated graph
would send the onnx backend's caller to another backend. A file not listed (a user's own
``--weights``) is checked as before, for its shapes and finite values. Writing a network into
such a folder (:func:`record`) updates its line. No torch here: the onnx path in a stock Blender
uses it too.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from specgen_addon.common.errors import WeightsError
from specgen_addon.common.atomic_io import atomic_write

SUMS_NAME = "SHA256SUMS"
#: (path, size, mtime_ns) -> sha256 hex, so a file is hashed once per process while unchanged.
_CACHE: dict[tuple[str, int, int], str] = {}


class DamagedWeightsError(WeightsError):
    """A listed network file's SHA-256 differs from its ``SHA256SUMS`` line."""


def sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file (cached while its size and modification time are unchanged)."""
    st = os.stat(path)
    key = (os.path.abspath(path), st.st_size, st.st_mtime_ns)
    if key not in _CACHE:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        _CACHE[key] = h.hexdigest()
    return _CACHE[key]


def read_sums(folder: str | os.PathLike) -> dict[str, str]:
    """``{file name: hex}`` of ``folder/SHA256SUMS`` ({} when there is none)."""
    path = Path(folder) / SUMS_NAME
    if not path.is_file():
        return {}
    sums = {}
    for line in path.read_text().splitlines():
        parts = line.strip().split(maxsplit=1)
        if len(parts) == 2 and not line.startswith("#"):
            sums[parts[1].lstrip("*")] = parts[0].lower()
    return sums


def verify(path: str | os.PathLike) -> None:
    """Refuse ``path`` when its folder's ``SHA256SUMS`` lists it with another sum."""
    path = Path(path)
    expected = read_sums(path.parent).get(path.name)
    if expected is None:
        return
    if sha256(path) != expected:
        raise DamagedWeightsError(
            f"{path}: damaged or modified network file (its SHA-256 does not match "
            f"{path.parent / SUMS_NAME}); reinstall it, or re-export it to record the new sum")


def record(path: str | os.PathLike) -> None:
    """After writing ``path``: update its line where its folder keeps a ``SHA256SUMS``."""
    path = Path(path)
    sums_path = path.parent / SUMS_NAME
    if not sums_path.is_file():
        return
    sums = read_sums(path.parent)
    sums[path.name] = sha256(path)
    with atomic_write(sums_path, overwrite=True) as tmp:
        tmp.write_text("".join(f"{h}  {n}\n" for n, h in sorted(sums.items())))
