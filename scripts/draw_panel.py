"""Draw the SpecGen N-panel as Blender lays it out, without a Blender window.

The bpy module has no UI (and no Blender binary is available here to run under Xvfb), so this is
not a screenshot: it runs the panel's real ``draw()`` against a layout that records every call
(columns, properties with their RNA labels and current values, operator buttons), then paints the
recorded rows in Blender's dark theme with matplotlib. ``tests/ops/test_blender_addon.py`` checks the
same recording.

    .venv/bin/python scripts/draw_panel.py docs/figures/panel.png
    .venv/bin/python scripts/draw_panel.py docs/figures/panel_photo_lights.png --lights
"""

from __future__ import annotations

import runpy
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

REPO = Path(__file__).resolve().parents[1]


@dataclass
class Row:
    kind: str           # "prop", "operator", "template", "label", "progress", "heading"
    label: str
    value: str = ""
    name: str = ""      # property / operator identifier
    enabled: bool = True


@dataclass
class RecordingLayout:
    """Stands in for ``bpy.types.UILayout``: records what the panel draws, in order."""

    rows: list[Row] = field(default_factory=list)
    use_property_split: bool = False
    use_property_decorate: bool = True
    scale_y: float = 1.0
    enabled: bool = True

    def _child(self, heading: str = "") -> "RecordingLayout":
        if heading:
            self.rows.append(Row("heading", heading))
        child = RecordingLayout(self.rows)
        child.enabled = self.enabled
        return child

    def column(self, heading: str = "", align: bool = False) -> "RecordingLayout":
        return self._child(heading)

    def row(self, heading: str = "", align: bool = False) -> "RecordingLayout":
        return self._child(heading)

    def prop(self, data, name: str, text: str | None = None, **_):
        rna = data.bl_rna.properties[name]
        value = getattr(data, name)
        if rna.type == "ENUM":
            value = next((i.name for i in rna.enum_items if i.identifier == value), value)
        elif rna.type == "FLOAT":
            value = f"{value:.{max(0, rna.precision)}f}" if rna.subtype != "FACTOR" else f"{value:.2f}"
        elif rna.type == "BOOLEAN":
            value = "[x]" if value else "[ ]"
        elif rna.type == "STRING" and not value:
            value = "—"
        self.rows.append(Row("prop", rna.name if text is None else text, str(value), name, self.enabled))

    def operator(self, idname: str, text: str | None = None, icon: str = "", **_):
        import bpy

        module, op = idname.split(".")
        label = getattr(getattr(bpy.ops, module), op).get_rna_type().name
        self.rows.append(Row("operator", label if not text else text, icon, idname, self.enabled))

    def template_ID(self, data, name: str, open: str = "", **_):
        value = getattr(data, name)
        self.rows.append(Row("template", data.bl_rna.properties[name].name,
                             value.name if value is not None else "New / Open…", name, self.enabled))

    def panel(self, idname: str, default_closed: bool = False):
        """A collapsible section (Blender 4.1+ layout panels), recorded open."""
        return self._child(), self._child()

    def template_list(self, listtype: str, list_id: str, data, propname: str, active_data, active_propname: str,
                      **_):
        for item in getattr(data, propname):
            values = [_value_text(k, getattr(item, k.identifier)) for k in item.bl_rna.properties
                      if k.identifier not in ("rna_type", "name")]
            self.rows.append(Row("label", "  ".join(values), "", propname, self.enabled))

    def label(self, text: str = "", icon: str = "", **_):
        self.rows.append(Row("label", text, icon))

    def progress(self, factor: float = 0.0, type: str = "BAR", text: str = ""):
        self.rows.append(Row("progress", text, f"{factor:.2f}"))

    def separator(self, **_):
        self.rows.append(Row("heading", ""))

    def template_icon(self, icon_value: int = 0, scale: float = 1.0, **_):
        self.rows.append(Row("icon", "", str(icon_value)))


def _value_text(rna, value) -> str:
    """A list item's value as the UI shows it (angles in degrees)."""
    if rna.type != "FLOAT":
        return str(value)
    if rna.subtype == "ANGLE":
        import math

        return f"{math.degrees(value):.0f}°"
    return f"{value:.4g}"


def record_panel(context) -> list[Row]:
    """Run ``SPECGEN_PT_main.draw`` against a recording layout; the add-on must be registered."""
    import bpy

    layout = RecordingLayout()
    bpy.types.SPECGEN_PT_main.draw(_PanelProxy(layout), context)
    return layout.rows


class _PanelProxy:
    def __init__(self, layout):
        self.layout = layout


def paint(rows: list[Row], path: Path, title: str = "SpecGen") -> Path:
    """Paint recorded rows as a Blender-like sidebar panel (dark theme) into a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyBboxPatch

    height = 0.42 * (len(rows) + 1.5)
    fig = plt.figure(figsize=(4.2, height), dpi=110)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.set_xlim(0, 10)
    ax.set_ylim(-(len(rows) + 1.2), 1)
    ax.axis("off")
    fig.patch.set_facecolor("#303030")
    ax.add_patch(FancyBboxPatch((0.15, 0.0), 9.5, 0.8, boxstyle="round,pad=0.02", fc="#3d3d3d", ec="none"))
    ax.text(0.45, 0.4, "▾  " + title, color="#e6e6e6", va="center", fontsize=10, weight="bold")
    ax.text(9.95, -0.5 * (len(rows) + 2), "SpecGen", color="#aaaaaa", rotation=270, va="center",
            ha="right", fontsize=8)
    y = -0.8
    for row in rows:
        y -= 1.0
        alpha = 1.0 if row.enabled else 0.45
        if row.kind == "heading":
            ax.text(0.5, y + 0.35, row.label, color="#9a9a9a", fontsize=8, va="center", alpha=alpha)
            y += 0.35
        elif row.kind in ("prop", "template"):
            ax.text(4.3, y + 0.35, row.label, color="#cfcfcf", fontsize=8, ha="right", va="center", alpha=alpha)
            ax.add_patch(FancyBboxPatch((4.5, y + 0.05), 4.9, 0.6, boxstyle="round,pad=0.03",
                                        fc="#545454" if row.kind == "prop" else "#4a4a4a", ec="none", alpha=alpha))
            ax.text(4.7, y + 0.35, row.value[:34], color="#ffffff", fontsize=8, va="center", alpha=alpha)
        elif row.kind == "operator":
            ax.add_patch(FancyBboxPatch((0.5, y + 0.02), 8.9, 0.7, boxstyle="round,pad=0.03",
                                        fc="#5a5a5a", ec="#6a6a6a", alpha=alpha))
            ax.text(4.95, y + 0.37, row.label, color="#ffffff", fontsize=9, ha="center", va="center", alpha=alpha)
        elif row.kind == "progress":
            ax.add_patch(FancyBboxPatch((0.5, y + 0.05), 8.9, 0.6, boxstyle="round,pad=0.03", fc="#4772b3", ec="none"))
            ax.text(4.95, y + 0.35, row.label, color="#ffffff", fontsize=8, ha="center", va="center")
        elif row.kind == "icon":  # an image preview (input thumbnail, preview sphere)
            ax.add_patch(FancyBboxPatch((4.5, y + 0.05), 1.2, 0.6, boxstyle="round,pad=0.03", fc="#222222", ec="#6a6a6a"))
        else:
            ax.text(0.6, y + 0.35, "i  " + row.label, color="#cfcfcf", fontsize=8, va="center")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, facecolor=fig.get_facecolor())
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    paths = [a for a in argv if not a.startswith("--")]
    out = Path(paths[0]) if paths else REPO / "docs" / "figures" / "panel.png"
    batch = SimpleNamespace(**runpy.run_path(str(REPO / "batch.py"), run_name="batch"))  # the headless entry

    pkg = batch.load_package()
    import bpy

    pkg.register()
    try:
        s = bpy.context.scene.specgen
        s.image_path = "//examples/sphere.png"
        s.atlas_json = "//specgen/sphere_lookup.json"
        if "--lights" in argv:   # the Photo section with the room's lights given
            import math

            s.photo.lighting = "LIGHTS"
            light = s.photo.lights.add()
            light.azimuth, light.elevation, light.power = math.radians(30), math.radians(20), 2.0
            s.photo.ambient = 0.05
        print(paint(record_panel(bpy.context), out))
    finally:
        pkg.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
