"""Reference spectral renderer (bpy-free): geometry, lights, environments, and the shading loop.

Typical use::

    from specgen_addon.render import sphere_geometry, DistantLight, Environment, render_spectral
    img = render_spectral(brdf, sphere_geometry(256), lights=[DistantLight((0, 0, 1))])
    img.spectral  # (256, 256, 21) radiance;  img.rgb  # linear sRGB

    scene = Scene(sphere_geometry(256), environment=Environment.from_file(path))  # reuse for many BRDFs
    gt, pred = scene.render_spectral(gt_brdf), scene.render_spectral(pred_brdf)
"""

from specgen_addon.render.environment import Environment, uplift_basis
from specgen_addon.render.geometry import Geometry, OrthographicCamera, sphere_geometry
from specgen_addon.render.lights import DistantLight
from specgen_addon.render.renderer import RenderResult, Scene, render_rgb, render_spectral
from specgen_addon.render.sampling import EnvSampling

__all__ = ["DistantLight", "EnvSampling", "Environment", "Geometry", "OrthographicCamera",
           "RenderResult", "Scene", "render_rgb", "render_spectral", "sphere_geometry", "uplift_basis"]
