"""Capture a mesh's world-space normal map and mask as seen by the reference renderer's camera.

Runs in Blender or with the ``bpy`` module; the core (``specgen_addon``) only reads the ``.npz``
this writes. Rays are cast orthographically through pixel centres (no rendering, no sampling
noise) against the evaluated mesh; the hit triangle's corner normals are interpolated
barycentrically (:func:`specgen_addon.render.geometry.smooth_normal`), so smooth shading and
modifiers (e.g. subdivision) are honoured.

Frames: Blender is z-up; the renderer's world is +x right, +y up, +z towards the camera, which is
Blender's front view (camera at −Y looking +Y): renderer ``(x, y, z)`` = Blender ``(X, Z, −Y)``.

Command line (used by :mod:`specgen_addon.evaluation.protocol` through a subprocess)::

    python ops/normal_map.py --suzanne --resolution 128 --out suzanne_128.npz
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from specgen_addon.render.geometry import smooth_normal


def capture_normal_map(obj, resolution: int, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Normal map (H, W, 3, renderer frame) and mask (H, W) of ``obj`` filling the frame.

    The object's X/Z bounding box is centred and scaled to span ``1 − margin`` of the [−1, 1]
    image square (pixel centres as :func:`specgen_addon.render.geometry.pixel_grid`).
    """
    import bpy
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(depsgraph).to_mesh()
    mesh.calc_loop_triangles()
    world = obj.matrix_world
    verts = np.array([tuple(world @ v.co) for v in mesh.vertices], dtype=np.float64)
    rot = np.array(world.to_3x3().inverted().transposed(), dtype=np.float64)
    corner_n = np.array([tuple(c.vector) for c in mesh.corner_normals], dtype=np.float64) @ rot.T
    tris = [tuple(t.vertices) for t in mesh.loop_triangles]
    tri_loops = np.array([tuple(t.loops) for t in mesh.loop_triangles], dtype=np.int64)
    tri_verts = np.array(tris, dtype=np.int64)
    tree = BVHTree.FromPolygons([tuple(v) for v in verts], tris)

    lo, hi = verts.min(axis=0), verts.max(axis=0)
    centre = (lo + hi) / 2.0
    half = max(hi[0] - lo[0], hi[2] - lo[2]) / 2.0 / (1.0 - margin)
    coords = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    normals = np.zeros((resolution, resolution, 3))
    mask = np.zeros((resolution, resolution), dtype=bool)
    y0 = lo[1] - 1.0
    for row in range(resolution):
        z = centre[2] + (-coords[row]) * half          # row 0 = top of the picture
        for col in range(resolution):
            x = centre[0] + coords[col] * half
            hit, _, index, _ = tree.ray_cast(Vector((x, y0, z)), Vector((0.0, 1.0, 0.0)))
            if hit is None:
                continue
            n = smooth_normal(np.array(tuple(hit)), verts[tri_verts[index]], corner_n[tri_loops[index]])
            normals[row, col] = (n[0], n[2], -n[1])      # Blender → renderer frame
            mask[row, col] = True
    obj.evaluated_get(depsgraph).to_mesh_clear()
    return normals, mask


def suzanne(subdivision_levels: int = 2):
    """A fresh scene holding Blender's Suzanne, subdivided and smooth-shaded."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.active_object
    mod = obj.modifiers.new("subdivision", "SUBSURF")
    mod.levels = subdivision_levels
    mod.render_levels = subdivision_levels
    for poly in obj.data.polygons:
        poly.use_smooth = True
    return obj


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suzanne", action="store_true", help="capture Blender's Suzanne")
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--out", required=True, help=".npz with 'normals' (H,W,3) and 'mask' (H,W)")
    args = parser.parse_args(argv)
    if not args.suzanne:
        parser.error("only --suzanne is supported from the command line")
    normals, mask = capture_normal_map(suzanne(), args.resolution)
    np.savez(args.out, normals=normals.astype(np.float32), mask=mask)
    return 0


if __name__ == "__main__":
    sys.exit(main())
