"""The panel and the command line offer what the core can do, read from the core's own lists: a
new way of generating or a new output format is added in the core, never typed again in ops/."""

from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from addon_modules import addon_module

from specgen_addon.brdf.formats.export import OUTPUT_SUFFIXES
from specgen_addon.cli.app import build_parser
from specgen_addon.generate.models import DEFAULT_MODEL, MODELS

properties = addon_module("ops.properties")
pytestmark = pytest.mark.blender


def test_the_panels_model_menu_and_the_command_lines_model_are_the_cores_list(registered_addon):
    menu = registered_addon.specgen.bl_rna.properties["model"]
    assert [item.identifier for item in menu.enum_items] == list(MODELS)
    assert menu.default == DEFAULT_MODEL
    infer = build_parser()._subparsers._group_actions[0].choices["infer"]
    model = next(a for a in infer._actions if "--model" in a.option_strings)
    assert list(model.choices) == list(MODELS) and model.default == DEFAULT_MODEL


def test_export_offers_every_format_the_core_writes(registered_addon):
    offered = bpy.ops.specgen.export_brdf.get_rna_type().properties["filter_glob"].default
    assert sorted(offered.split(";")) == sorted(f"*{s}" for s in OUTPUT_SUFFIXES)
