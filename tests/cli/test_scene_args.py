"""Whole-scene command-line values (frame ranges, --apply specs), output names and the render-time
model: all checked without Blender."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from ops import naming
from specgen_addon.common.errors import SpecGenError
from specgen_addon.render.cycles_time_estimate import RenderCost, fit_cost, format_duration
from specgen_addon.cli.scene_args import ApplySpec, check_objects, parse_apply, parse_frames


@pytest.mark.parametrize("text,frames", [("1-10", list(range(1, 11))), ("1,3,5-7", [1, 3, 5, 6, 7]),
                                         ("12", [12]), (" 4 , 2-3,3", [2, 3, 4]), ("-2-1", [-2, -1, 0, 1])])
def test_frame_lists_and_ranges_parse_to_sorted_unique_frames(text, frames):
    assert parse_frames(text) == frames


@pytest.mark.parametrize("text,message", [("", "expected frames like"), ("1-", "expected frames"),
                                          ("a", "expected frames"), ("5-2", "runs backwards"),
                                          ("1-999999", "more than")])
def test_bad_frame_lists_are_one_sentence(text, message):
    with pytest.raises(SpecGenError, match=message):
        parse_frames(text)


def test_apply_spec_takes_a_photo_an_object_and_per_photo_lighting():
    assert parse_apply("a/photo.png:Cube") == ApplySpec(Path("a/photo.png"), "Cube")
    spec = parse_apply("C:/pics/ball.jpg:Suzanne:env=forest, rotation=30,exposure=2,key-light=on")
    assert spec.image == Path("C:/pics/ball.jpg") and spec.object_name == "Suzanne"
    base = argparse.Namespace(input_env="canonical", input_rotation=0.0, input_exposure=1.0,
                              input_key_light=None)
    ns = spec.namespace(base)
    assert (ns.input_env, ns.input_rotation, ns.input_exposure, ns.input_key_light) == ("forest", 30.0, 2.0, True)
    assert parse_apply("p.png:Cube:rotation=90").namespace(base).input_env == "canonical"
    assert base.input_env == "canonical" and base.input_rotation == 0.0   # the command's own untouched


@pytest.mark.parametrize("spec,message", [
    ("photo.png", "expected IMAGE:OBJECT"), (":Cube", "expected IMAGE:OBJECT"),
    ("p.png:", "expected IMAGE:OBJECT"), ("p.png:Cube:colour=red", "unknown option 'colour'"),
    ("p.png:Cube:rotation=left", "rotation must be a number"),
    ("p.png:Cube:key-light=maybe", "key-light must be on or off"),
    ("p.png:Cube:env=", "env needs a value"), ("p.png:Cube:env=a,env=b", "given twice"),
    ("p.png:Cube:env=a,rotation", "key=value pairs"),
    ("p.png:Cube:model=soap", "model must be one of network, thin-film")])
def test_bad_apply_specs_are_one_sentence(spec, message):
    with pytest.raises(SpecGenError, match=message):
        parse_apply(spec)


def test_apply_targets_must_be_meshes_of_the_scene_named_once():
    objects = {"Cube": "MESH", "Light": "LIGHT"}
    check_objects([parse_apply("a.png:Cube")], objects, "Scene")
    with pytest.raises(SpecGenError, match="has no object 'Sphere'"):
        check_objects([parse_apply("a.png:Sphere")], objects, "Scene")
    with pytest.raises(SpecGenError, match="is a light, not a mesh"):
        check_objects([parse_apply("a.png:Light")], objects, "Scene")
    with pytest.raises(SpecGenError, match="more than one photo"):
        check_objects([parse_apply("a.png:Cube"), parse_apply("b.png:Cube")], objects, "Scene")


def test_render_outputs_are_named_after_scene_camera_and_frame():
    assert naming.render_output_name("Scene", "Camera", 1) == "Scene_Camera_f0001.exr"
    assert naming.render_output_name("My Shot", "cam.001", 12345) == "My_Shot_cam_001_f12345.exr"
    assert naming.render_output_name("S", None, -3) == "S_nocamera_f-0003.exr"


def test_render_cost_model_separates_overhead_from_samples():
    truth = RenderCost(overhead_s=0.4, rate_s=2e-6)
    cost = fit_cost(4096, (1, 4), (truth.render_s(4096, 1), truth.render_s(4096, 4)))
    assert cost.overhead_s == pytest.approx(0.4) and cost.rate_s == pytest.approx(2e-6)
    assert cost.predict(7, 1920 * 1080, 16) == pytest.approx(7 * (0.4 + 2e-6 * 1920 * 1080 * 16))
    noisy = fit_cost(4096, (1, 4), (0.5, 0.49))    # timer noise: never a negative rate
    assert noisy.rate_s > 0 and noisy.overhead_s >= 0
    adaptive = truth.with_adaptive(256, 4096, truth.render_s(256, 4096 // 4))  # a quarter taken
    assert adaptive.sample_fraction == pytest.approx(0.25)
    assert adaptive.render_s(1000, 4096) == pytest.approx(truth.render_s(1000, 1024))
    assert truth.with_adaptive(256, 64, 1e3).sample_fraction == 1.0       # never above all samples
    assert [format_duration(s) for s in (45, 210, 9000)] == ["45 s", "3.5 min", "2.5 h"]
    with pytest.raises(SpecGenError):
        fit_cost(4096, (4, 4), (1.0, 1.0))
