"""Check a Wavefront OBJ mesh before Blender imports it (Blender's importer renders garbage black).

Refused, with the file and line: an unreadable file, a ``v`` line with fewer than three numbers or
with NaN/Inf coordinates, a face with fewer than three corners or an index outside the vertices
(OBJ indices are 1-based; negative ones count back from the last vertex read), a file with no
face (vertices only) and a file over :data:`MAX_OBJ_BYTES`. Pure Python and numpy-free: it
streams the file line by line.
"""

from __future__ import annotations

import math
import os

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.limits import check_input_file

MAX_OBJ_BYTES = 1 << 30   # 1 GiB
MAX_OBJ_VERTICES = 20_000_000


def check_obj(path: str | os.PathLike) -> tuple[int, int]:
    """Validate an OBJ file; returns ``(vertex count, face count)``."""
    path = check_input_file(path, "mesh file (sphere, suzanne or an .obj path)")
    if path.suffix.lower() != ".obj":
        raise SpecGenError(f"{path}: mesh must be sphere, suzanne or a Wavefront .obj file")
    size = path.stat().st_size
    if size > MAX_OBJ_BYTES:
        raise SpecGenError(f"{path}: mesh file is {size / 2**30:.1f} GiB, the limit is "
                           f"{MAX_OBJ_BYTES / 2**30:.0f} GiB")
    n_vertices = n_faces = 0

    def bad(line_no: int, why: str) -> SpecGenError:
        return SpecGenError(f"{path}: line {line_no}: {why}")

    try:
        with open(path, "r", encoding="utf-8", errors="replace") as fh:
            for line_no, line in enumerate(fh, 1):
                parts = line.split("#", 1)[0].split()
                if not parts:
                    continue
                key = parts[0]
                if key == "v":
                    try:
                        xyz = [float(x) for x in parts[1:4]]
                    except ValueError:
                        raise bad(line_no, "vertex coordinates are not numbers") from None
                    if len(xyz) < 3:
                        raise bad(line_no, "vertex with fewer than 3 coordinates (truncated file?)")
                    if not all(math.isfinite(c) for c in xyz):
                        raise bad(line_no, "vertex with NaN or infinite coordinates")
                    n_vertices += 1
                    if n_vertices > MAX_OBJ_VERTICES:
                        raise bad(line_no, f"more than {MAX_OBJ_VERTICES:,} vertices")
                elif key == "f":
                    corners = parts[1:]
                    if len(corners) < 3:
                        raise bad(line_no, "face with fewer than 3 corners (truncated file?)")
                    for c in corners:
                        try:
                            i = int(c.split("/", 1)[0])
                        except ValueError:
                            raise bad(line_no, f"face index {c!r} is not a number") from None
                        resolved = i if i > 0 else n_vertices + 1 + i
                        if i == 0 or not 1 <= resolved <= n_vertices:
                            raise bad(line_no, f"face index {i} is out of range "
                                               f"(1–{n_vertices} vertices so far)")
                    n_faces += 1
    except OSError as exc:
        raise SpecGenError(f"{path}: cannot read the mesh file ({exc.strerror})") from None
    if n_vertices < 3:
        raise SpecGenError(f"{path}: mesh has {n_vertices} vertices; at least 3 are needed")
    if n_faces == 0:
        raise SpecGenError(f"{path}: mesh has {n_vertices} vertices but no faces (nothing to render)")
    return n_vertices, n_faces
