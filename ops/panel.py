"""The "SpecGen" tab of the 3D viewport sidebar (N-panel)."""

from __future__ import annotations

import bpy

from specgen_addon.generate.models import MODELS

from .photo_panel import draw_photo


class SPECGEN_PT_main(bpy.types.Panel):
    """Input image, spectral sampling, render settings and the three actions."""

    bl_idname = "SPECGEN_PT_main"
    bl_label = "SpecGen"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "SpecGen"

    def draw(self, context):
        s = context.scene.specgen
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False

        col = layout.column(heading="Input")
        col.template_ID(s, "image", open="image.open")
        if s.image is None:
            col.prop(s, "image_path")
        else:
            _thumbnail(col, s.image)
        col.prop(s, "weights_path")

        draw_photo(layout, s.photo)
        col = layout.column(heading="BRDF")
        col.prop(s, "model")
        if MODELS[s.model].refines:
            col.prop(s, "refine")

        col = layout.column(heading="Spectrum", align=True)
        col.prop(s, "wl_min", text="Wavelengths (nm)")
        col.prop(s, "wl_max", text="To")
        col.prop(s, "bands")
        col = layout.column()
        col.prop(s, "lookup_resolution")
        col.prop(s, "basis_tolerance")

        col = layout.column(heading="Render", align=True)
        col.prop(s, "render_mode")
        if s.render_mode == "EXACT":
            col.prop(s, "samples")
            col.prop(s, "resolution")
            col.prop(s, "env_samples")
        else:  # the full-scene mode renders with the scene's own settings: shown and edited here
            _scene_render_settings(layout, context.scene)
        col = layout.column()
        col.prop(s, "quick_preview")
        col.prop(s, "output_dir")
        col.prop(s, "overwrite")
        col.prop(s, "overwrite_outputs")
        col.prop(s, "export_table")

        col = layout.column(heading="Material")
        col.template_ID(s, "material")
        if s.material is not None:
            preview = bpy.data.images.get(s.material.get("specgen_preview", ""))
            if preview is not None:
                _thumbnail(col, preview)
            col.operator("specgen.export_brdf", icon="EXPORT")   # .bsdf / .binary for other renderers
        if s.refine_residual >= 0.0:
            col.label(text=f"Refined photo match: {s.refine_residual:.1f} dB", icon="GRAPH")
        others = [m.name for m in bpy.data.materials if m.get("specgen") and m != s.material]
        for name in others:
            col.label(text=name, icon="MATERIAL")

        layout.use_property_split = False
        col = layout.column(align=True)
        col.scale_y = 1.3
        col.enabled = not s.running
        col.operator("specgen.generate_brdf", icon="MATERIAL")
        col.operator("specgen.apply", icon="CHECKMARK")
        col.operator("specgen.render_stack", icon="RENDER_STILL")
        if s.render_mode == "FULL_SCENE":
            row = layout.row()
            row.enabled = not s.running
            row.operator("specgen.estimate_time", icon="TIME")
            if s.estimate:
                layout.label(text=s.estimate, icon="TIME")
        if s.running:
            layout.progress(factor=s.progress, type="BAR", text=f"{s.running}… (Esc cancels)")
        elif s.atlas_json:
            layout.label(text=f"Baked: {bpy.path.basename(s.atlas_json)}", icon="INFO")
            if s.refine_summary:
                layout.label(text=s.refine_summary, icon="IMAGE_REFERENCE")
        mat = getattr(context.object, "active_material", None)
        if mat is not None and "specgen_fit_delta_e" in mat:  # the closures' rendered colour error
            de = mat["specgen_fit_delta_e"]
            layout.label(text=f"Closures vs table: ΔE2000 {de:.2f}"
                         + (" (bounces and F12 only; the direct light is exact)" if de > 2.0 else ""),
                         icon="ERROR" if de > 2.0 else "INFO")
        elif mat is not None and "specgen_fit_error" in mat:
            layout.label(text=f"Closure fit error: {100 * mat['specgen_fit_error']:.1f} %",
                         icon="INFO")


def _scene_render_settings(layout, scene) -> None:
    """The scene's resolution, samples and denoising (its own properties, so edits are the
    scene's), and what the quick preview would use instead."""
    r = scene.render
    col = layout.column(align=True)
    col.prop(r, "resolution_x", text="Resolution X")
    col.prop(r, "resolution_y", text="Y")
    col.prop(r, "resolution_percentage", text="%")
    cycles = getattr(scene, "cycles", None)
    if cycles is not None:                      # Cycles' settings exist once Cycles is loaded
        col = layout.column()
        col.prop(cycles, "samples", text="Scene Samples")
        col.prop(cycles, "use_denoising", text="Denoise")
    if scene.specgen.quick_preview:
        from .render_settings import PREVIEW_PERCENT, PREVIEW_SAMPLES

        pct = min(r.resolution_percentage, PREVIEW_PERCENT)
        w, h = int(r.resolution_x * pct / 100), int(r.resolution_y * pct / 100)
        spp = min(cycles.samples, PREVIEW_SAMPLES) if cycles is not None else PREVIEW_SAMPLES
        layout.label(text=f"Preview: {w}×{h}, {spp} samples, no denoising", icon="INFO")


def _thumbnail(layout, image) -> None:
    """Draw an image datablock's preview (the input photo, a material's preview sphere)."""
    try:
        icon = image.preview_ensure().icon_id
    except (AttributeError, RuntimeError):  # no previews without a UI (background mode)
        return
    layout.template_icon(icon_value=icon, scale=6.0)


CLASSES = (SPECGEN_PT_main,)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
