"""Full Scene mode: direct light on SpecGen surfaces from the exact lookups, bounces from closures.

The full-scene render draws SpecGen materials with their fitted native closure stack (Lambert +
GGX lobes, :mod:`specgen_addon.bake.closure_fit.closures`), so Cycles can bounce light off them like any other
material. A stack of a few lobes cannot hold every generated table (docs/blender.md, "Full Scene
fidelity"), and what a viewer sees first is the direct light on the SpecGen surface itself. So the
job composes each pixel as

    L = L_closures(all paths) − L_closures(direct, SpecGen surfaces) + L_exact(direct, SpecGen surfaces)

* ``L_closures(all paths)``: the ordinary band-group render of the whole scene;
* ``L_closures(direct, …)``: the same band groups with no bounces, every other object a holdout
  (it still occludes and casts shadows), lights the exact mode cannot evaluate (spot, area) hidden,
  the background not drawn (transparent film; the world still lights);
* ``L_exact(direct, …)``: the exact mode's OSL render (:class:`.render.SpectralRenderJob`) of the
  same camera, other objects held out the same way.

Both direct terms cover the same pixels with the same coverage, so their difference is exactly the
SpecGen surfaces' correction, also at pixels that mix a SpecGen surface with something else. The
correction replaces the closures' direct light from suns, point lights and the world; light that
reaches a SpecGen surface after a bounce, and from spot and area lights and emissive objects, stays
with the closures (whose rendered error the job reports per material).
"""

from __future__ import annotations

from typing import Callable, Generator

import bpy
import numpy as np

from specgen_addon.bake import lookup as bake
from specgen_addon.common.errors import Cancelled, SpecGenError
from .render import (SavedAttributes, SpectralRenderJob, is_specgen_material, script_node,
                     specgen_materials)
from .render_settings import band_render

#: Samples of the exact render at most (its suns and point lights are noiseless but for the pixel
#: filter; the environment is importance-sampled in the shader).
EXACT_SAMPLES_CAP = 64
#: Light types the exact shader evaluates; the others keep their closure light.
EXACT_LIGHTS = ("SUN", "POINT")
SURFACES = ("MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME")


def has_specgen(scene: bpy.types.Scene, warn: Callable[[str], None] = print) -> bool:
    """Whether a render-visible object of ``scene`` uses a SpecGen material and the exact lookups
    can light it (no more sun and point lights than the exact shader takes; else a warning)."""
    if not specgen_materials(scene):
        return False
    lights = [o.name for o in scene.objects
              if o.type == "LIGHT" and not o.hide_render and o.data.type in EXACT_LIGHTS]
    if len(lights) > bake.MAX_LIGHTS:
        warn(f"SpecGen: {len(lights)} sun and point lights, the exact lookups take "
             f"{bake.MAX_LIGHTS}: SpecGen surfaces show their native closures only")
        return False
    return True


def _holds_specgen(obj: bpy.types.Object) -> bool:
    return any(is_specgen_material(s.material) for s in getattr(obj, "material_slots", ()))


class DirectOnlySettings(SavedAttributes):
    """Scene settings of the closures' direct-light render of SpecGen surfaces; restored on exit."""

    def __init__(self, scene: bpy.types.Scene, world: bool = True):
        self.scene = scene
        self.world = world
        self.saved: list[tuple[object, str, object]] = []

    def __enter__(self) -> "DirectOnlySettings":
        sc = self.scene
        self._set(sc.cycles, "max_bounces", 0)          # camera hit + light sampling only
        self._set(sc.render, "film_transparent", True)  # the world lights but is not drawn
        if not self.world:                                # ... or not even that (see world_light)
            self._set(sc, "world", None)
        for obj in sc.objects:
            if obj.type == "LIGHT" and obj.data.type not in EXACT_LIGHTS and not obj.hide_render:
                self._set(obj, "hide_render", True)
            elif obj.type in SURFACES and not _holds_specgen(obj) and not obj.is_holdout:
                self._set(obj, "is_holdout", True)       # occludes, shadows, draws nothing
        self.slots = HeldOutSlots(sc).__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.slots.__exit__(*exc)
        self._restore_attributes()


class HeldOutSlots(SavedAttributes):
    """The other material slots of objects that hold a SpecGen material, as holdouts (the two
    direct-light renders must both leave them out; the Exact mode would read their albedo)."""

    def __init__(self, scene: bpy.types.Scene):
        self.scene = scene
        self.saved: list[tuple[object, str, object]] = []
        self.holdout: bpy.types.Material | None = None

    def __enter__(self) -> "HeldOutSlots":
        for obj in self.scene.objects:
            if obj.type in SURFACES and _holds_specgen(obj):
                for slot in obj.material_slots:
                    if slot.material is not None and not is_specgen_material(slot.material):
                        self._set(slot, "material", self._material())
        return self

    def _material(self) -> bpy.types.Material:
        if self.holdout is None:
            self.holdout = bpy.data.materials.new("SpecGen holdout")
            tree = self.holdout.node_tree
            tree.nodes.clear()
            out = tree.nodes.new("ShaderNodeOutputMaterial")
            tree.links.new(tree.nodes.new("ShaderNodeHoldout").outputs[0], out.inputs["Surface"])
        return self.holdout

    def __exit__(self, *exc) -> None:
        self._restore_attributes()
        if self.holdout is not None:
            bpy.data.materials.remove(self.holdout)


def _resample(spectral: np.ndarray, from_nm: np.ndarray, to_nm: np.ndarray) -> np.ndarray:
    """(H, W, Λ_from) → (H, W, Λ_to), linear in λ (held beyond the ends)."""
    from specgen_addon.spectral.spectra import interpolation_matrix

    if from_nm.size == to_nm.size and np.allclose(from_nm, to_nm):
        return spectral
    return spectral @ interpolation_matrix(from_nm, to_nm)


def world_light(scene: bpy.types.Scene, warn: Callable[[str], None] = print) -> bool:
    """Whether the exact lookups can take the world's light (one Background node: a colour, or an
    equirect Environment Texture rotated about Z); if not, a warning says why and the world's
    direct light on SpecGen surfaces stays with the closures (both direct terms leave it out)."""
    from .render import world_environment

    try:
        world_environment(scene)
    except SpecGenError as exc:
        warn(f"SpecGen: {str(exc).split(';')[0]}: the world's light on SpecGen surfaces comes from "
             "their native closures; suns and point lights from the exact lookups")
        return False
    return True


def exact_direct_steps(scene: bpy.types.Scene, wavelengths_nm: np.ndarray, shape: tuple[int, int],
                       warn: Callable[[str], None] = print, world: bool = True,
                       interactive: bool = False) -> Generator[float | None, None, np.ndarray | None]:
    """The exact mode's direct light on SpecGen surfaces (H, W, Λ) at ``wavelengths_nm``, other
    objects held out, as a generator: it yields the fraction done after each Cycles render (None
    while an ``interactive`` render runs as Blender's render job, which Esc stops inside the
    render: :func:`.render_settings.band_render`) and returns the stack; it returns None (with a
    warning saying why) when the exact mode cannot render the scene. A cancelled render raises
    :class:`~specgen_addon.common.errors.Cancelled`; the shader's sockets and the held-out slots
    are put back either way."""
    r = scene.render
    size = (round(r.resolution_x * r.resolution_percentage / 100),
            round(r.resolution_y * r.resolution_percentage / 100))
    if (size[1], size[0]) != tuple(shape):
        warn("SpecGen: the render is cropped to a border; SpecGen surfaces show the native "
             "closure stack only (no exact direct light)")
        return None
    samples = max(1, min(int(scene.cycles.samples), EXACT_SAMPLES_CAP))

    def relay(msg: str) -> None:  # spot/area lights and emitters: the closures carry them here
        if "ignored by the exact mode" not in msg and "does not light the exact mode" not in msg:
            warn(msg)

    job = SpectralRenderJob(scene, None, samples=samples, resolution=size, warn=relay,
                            holdout_others=True, world=world,
                            render_call=lambda: band_render(scene, None, interactive))
    # the exact job leaves its lights on the shader's sockets: put back what the file had
    sockets = [(sock, sock.default_value if isinstance(sock.default_value, (int, float, str))
                else tuple(sock.default_value))
               for mat in specgen_materials(scene) if script_node(mat) is not None
               for sock in script_node(mat).inputs if hasattr(sock, "default_value")]
    try:
        with HeldOutSlots(scene):
            yield from job.steps()
    except Cancelled:
        raise
    except SpecGenError as exc:
        warn(f"SpecGen: exact direct light unavailable ({exc}); SpecGen surfaces show the native "
             "closure stack only")
        return None
    finally:
        for sock, value in sockets:
            sock.default_value = value
    return _resample(job.spectral, job.wavelengths_nm, np.asarray(wavelengths_nm, np.float64))


def compose(full: np.ndarray, closure_direct: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """``full − closure_direct + exact`` (H, W, Λ), clipped at 0 (noise in the two direct terms)."""
    return np.maximum(full - closure_direct + exact, 0.0).astype(np.float32)


def report_fit(name: str, fit, exact: bool, warn: Callable[[str], None] = print,
               log: Callable[[str], None] = print) -> float | None:
    """Say how far material ``name``'s closure stack renders from its table (the fit's rendered
    ΔE2000, :mod:`specgen_addon.bake.closure_fit.fit_check`) and what that touches in this render: with
    ``exact`` direct light only the bounces and F12/viewport; without it, everything the Full Scene
    render shows of the material. Above :data:`~specgen_addon.bake.closure_fit.fit_check.WARN_DELTA_E` a
    warning names the material and the faithful alternative. Returns the ΔE2000 (None for a
    material baked before it was measured)."""
    from specgen_addon.bake.closure_fit.fit_check import CHECK_LIGHTS, WARN_DELTA_E

    de = fit.rendered_error
    if de is None:
        log(f"SpecGen: material {name!r}: native closure fit, worst band error "
            f"{100 * fit.max_error:.1f} % (relative RMS; Apply it again for its rendered error)")
        return None
    what = f"its native closures render ΔE2000 {de:.2f} from its table ({len(CHECK_LIGHTS)} lights)"
    if de <= WARN_DELTA_E:
        log(f"SpecGen: material {name!r}: {what}")
    elif exact:
        warn(f"SpecGen: material {name!r}: {what}; Full Scene draws its direct light exactly, but "
             "light it bounces onto itself or other objects, and the F12/viewport stand-in, "
             "carry that error")
    else:
        warn(f"SpecGen: material {name!r}: {what}, and Full Scene shows it so; the Exact mode "
             "renders it faithfully (direct light)")
    return de
