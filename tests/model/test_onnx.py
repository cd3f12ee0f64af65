"""ONNX export: onnxruntime reproduces the torch model (the Blender path runs without torch)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from specgen_addon.model.runtime import inference as infer
from specgen_addon.common.errors import WeightsError
from specgen_addon.model import Config, SpecGen, load_weights, save_weights
from specgen_addon.model.runtime.export_onnx import export_onnx
from tiny_model import TINY_MODEL

pytest.importorskip("onnxruntime")

SMALL = TINY_MODEL


@pytest.fixture(scope="module")
def exported(tmp_path_factory, tiny_network):
    d = tmp_path_factory.mktemp("onnx")
    model = tiny_network()
    torch.nn.init.normal_(model.fusion.branch_convs.weight, std=0.5)
    torch.nn.init.normal_(model.fusion.expand.weight, std=2.0)
    weights = save_weights(model, d / "w.pt")
    return weights, export_onnx(weights)


def test_export_writes_two_graphs_beside_the_weights(exported):
    weights, (tables, head) = exported
    assert tables == weights.with_name("w.tables.onnx") and head == weights.with_name("w.head.onnx")
    import onnx

    for p in (tables, head):
        onnx.checker.check_model(onnx.load(str(p)))


def test_onnx_and_torch_tables_agree(exported):
    weights, _ = exported
    x = np.random.default_rng(0).random((1, 3, 32, 32)).astype(np.float32)
    u = np.linspace(-1, 1, 7).astype(np.float32)       # another band count than at export
    a = infer.get_backend(weights, "onnx").make_tables(x, u)
    b = infer.get_backend(weights, "torch").make_tables(x, u)
    for ta, tb in zip(a, b):
        assert ta.shape == tuple(tb.shape)
        assert np.abs(ta - tb.numpy()).max() < 1e-4


def test_onnx_and_torch_generate_the_same_brdf(exported):
    from specgen_addon.photo.sphere_image import render_input
    from specgen_standins import RampMaterial

    weights, _ = exported
    image = render_input(RampMaterial(alpha=0.08), size=64)
    bands = np.array([420.0, 560.0, 660.0, 760.0])
    a = infer.generate_brdf(image, weights=weights, wavelengths_nm=bands, backend="onnx")
    b = infer.generate_brdf(image, weights=weights, wavelengths_nm=bands, backend="torch")
    ra = np.log1p(255 * a.values) / np.log1p(255)   # compare in the network's μ-law space
    rb = np.log1p(255 * b.values) / np.log1p(255)
    assert np.abs(ra - rb).max() < 1e-4


def _copy_without_head(exported, folder):
    """The exported weights and tables graph copied into ``folder``; the head graph is the test's."""
    import shutil

    weights, (tables, _) = exported
    shutil.copy(tables, folder / "w.tables.onnx")
    return Path(shutil.copy(weights, folder / "w.pt")), folder / "w.head.onnx"


def test_a_channels_first_head_exported_by_an_earlier_version_still_runs(exported, tmp_path):
    """Graphs exported before the low-rank head (channels-first, 12 inputs) give the same table."""
    from specgen_addon.photo.sphere_image import render_input
    from specgen_addon.model.runtime.fast import GridHeadChannelsFirst, GridTables, lambda_coords
    from specgen_standins import RampMaterial

    weights = exported[0]
    old, old_head = _copy_without_head(exported, tmp_path)
    model = load_weights(weights)
    with torch.no_grad():
        t = GridTables(model).eval()(torch.zeros(1, 3, 32, 32), lambda_coords(model, [420.0, 560.0, 660.0]))
    arranged = infer.channels_first_tables([x.numpy() for x in t])
    blocks = tuple(torch.from_numpy(np.ascontiguousarray(b)) for b in infer.channels_first_block(arranged, 0, 0, 2))
    varying = ({"nh": 1, "nd": 2}, {"nh": 1}, {"nd": 2}, {"nl": 0, "nh": 1}, {"nl": 0, "nd": 2}, {"nl": 0})
    names = infer.CHANNELS_FIRST_INPUTS
    dyn = {n: {axis + (1 if n.startswith("f") else 0): name for name, axis in varying[k % 6].items()}
           for k, n in enumerate(names)} | {"r": {0: "nl", 1: "nh", 2: "nd"}}
    with torch.no_grad():
        torch.onnx.export(GridHeadChannelsFirst(model).eval(), blocks, str(old_head),
                          input_names=list(names), output_names=["r"], dynamic_axes=dyn, opset_version=17,
                          dynamo=False)
    assert infer.get_backend(old, "onnx").head_layout == "channels_first"
    assert infer.get_backend(weights, "onnx").head_layout == "low_rank"
    image = render_input(RampMaterial(alpha=0.08), size=64)
    bands = np.array([420.0, 560.0, 660.0, 760.0])
    a = infer.generate_brdf(image, weights=old, wavelengths_nm=bands, backend="onnx")
    b = infer.generate_brdf(image, weights=weights, wavelengths_nm=bands, backend="onnx")
    ra, rb = (np.log1p(255 * x.values) / np.log1p(255) for x in (a, b))
    assert np.abs(ra - rb).max() < 1e-5


def test_a_low_rank_head_with_all_180_phi_d_nodes_fixed_still_runs(exported, tmp_path):
    """Heads exported before the φd runs take exactly 180 φd nodes: the backend gives them all 180
    and the table is the same as with the head that computes only the lookup's reach."""
    import onnx

    from specgen_addon.photo.sphere_image import render_input
    from specgen_standins import RampMaterial

    weights, (_, head) = exported
    old, old_head = _copy_without_head(exported, tmp_path)
    graph = onnx.load(str(head))
    fixed = 0
    for value in list(graph.graph.input) + list(graph.graph.output):
        for dim in value.type.tensor_type.shape.dim:
            if dim.dim_param == "np":
                dim.dim_value = 180                               # clears the symbolic name
                fixed += 1
    assert fixed == 7                                             # s2 s3 s6 f2 f3 f6 and r
    onnx.save(graph, str(old_head))
    assert not infer.get_backend(old, "onnx").phi_d_runs
    assert infer.get_backend(weights, "onnx").phi_d_runs
    image = render_input(RampMaterial(alpha=0.08), size=64)
    bands = np.array([420.0, 560.0, 660.0])
    a = infer.generate_brdf(image, weights=old, wavelengths_nm=bands, backend="onnx")
    b = infer.generate_brdf(image, weights=weights, wavelengths_nm=bands, backend="onnx")
    ra, rb = (np.log1p(255 * x.values) / np.log1p(255) for x in (a, b))
    assert np.abs(ra - rb).max() < 1e-5


def test_a_graph_that_is_no_specgen_head_is_refused_by_name(exported, tmp_path):
    import onnx
    from onnx import TensorProto, helper

    w, head = _copy_without_head(exported, tmp_path)
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [x],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), str(head))
    with pytest.raises(WeightsError, match="not a SpecGen head graph"):
        infer.get_backend(w, "onnx")


def test_onnx_backend_without_exported_graphs_says_how_to_make_them(tmp_path, tiny_network):
    weights = save_weights(tiny_network(), tmp_path / "lonely.pt")
    with pytest.raises(WeightsError, match="export-onnx"):
        infer.get_backend(weights, "onnx")


def test_a_model_with_a_detail_branch_exports_and_agrees(tmp_path):
    torch.manual_seed(0)
    model = SpecGen(Config(**{**SMALL, "image_size": 64}, detail_factor=2))
    torch.nn.init.normal_(model.encoder.detail[-1].weight, std=0.3)     # a trained, non-zero branch
    assert_exported_graphs_agree(save_weights(model, tmp_path / "d.pt"), size=64)


def assert_exported_graphs_agree(weights, size: int = 32) -> None:
    """Export ``weights`` and check onnxruntime's tables against torch's for one random input."""
    export_onnx(weights)
    x = np.random.default_rng(0).random((1, 3, size, size)).astype(np.float32)
    u = np.linspace(-1, 1, 5).astype(np.float32)
    for ta, tb in zip(infer.get_backend(weights, "onnx").make_tables(x, u),
                      infer.get_backend(weights, "torch").make_tables(x, u)):
        assert np.abs(ta - tb.numpy()).max() < 1e-4


def test_a_model_with_a_leaky_encoder_exports_and_agrees(tmp_path):
    torch.manual_seed(0)
    model = SpecGen(Config(**SMALL, encoder_negative_slope=0.2))
    with torch.no_grad():
        model.encoder.fc.bias[:8] = -5.0                      # latent units below zero: the slope shows
    weights = save_weights(model, tmp_path / "leaky.pt")
    export_onnx(weights)
    x = np.random.default_rng(1).random((1, 3, 32, 32)).astype(np.float32)
    u = np.linspace(-1, 1, 5).astype(np.float32)
    onnx = infer.get_backend(weights, "onnx").make_tables(x, u)
    for ta, tb in zip(onnx, infer.get_backend(weights, "torch").make_tables(x, u)):
        assert np.abs(ta - tb.numpy()).max() < 1e-4
    relu = save_weights(SpecGen(Config(**SMALL)), tmp_path / "relu.pt")
    model_relu = load_weights(relu)
    model_relu.load_state_dict(model.state_dict())             # the same weights without the slope
    save_weights(model_relu, relu)
    export_onnx(relu)
    assert any(np.abs(a - b).max() > 1e-3 for a, b in zip(onnx, infer.get_backend(relu, "onnx").make_tables(x, u)))


def _graph_tables(weights) -> tuple[np.ndarray, ...]:
    """The six grid tables onnxruntime makes from the graphs of ``weights`` for one fixed input."""
    x = np.random.default_rng(2).random((1, 3, 32, 32)).astype(np.float32)
    u = np.linspace(-1, 1, 4).astype(np.float32)
    return infer.get_backend(weights, "onnx").make_tables(x, u)


def test_float16_storage_is_lossless_and_halves_the_graph(tmp_path, tiny_network):
    model = tiny_network()
    weights = save_weights(model, tmp_path / "h.pt", half=True)       # as the shipped weights
    wide = save_weights(load_weights(weights), tmp_path / "wide.pt")  # the same numbers, float32 file
    export_onnx(weights, half=True)
    export_onnx(wide, half=False)
    half_graph, wide_graph = infer.onnx_paths(weights)[0], infer.onnx_paths(wide)[0]
    assert half_graph.stat().st_size < 0.7 * wide_graph.stat().st_size
    assert all(np.array_equal(a, b) for a, b in zip(_graph_tables(weights), _graph_tables(wide)))


def test_float16_storage_changes_no_output_of_float32_weights(tmp_path, tiny_network):
    model = tiny_network()
    a = save_weights(model, tmp_path / "a.pt")            # float32 numbers float16 cannot hold
    b = save_weights(model, tmp_path / "b.pt")
    export_onnx(a, half=True)
    export_onnx(b, half=False)
    assert all(np.array_equal(ta, tb) for ta, tb in zip(_graph_tables(a), _graph_tables(b)))


def test_onnx_backend_needs_only_the_graphs(tmp_path, tiny_network):
    # the extension ships the graphs without the .pt (torch reads only the .pt)
    weights = save_weights(tiny_network(), tmp_path / "alone.pt")
    export_onnx(weights)
    before = _graph_tables(weights)
    weights.unlink()
    after = _graph_tables(weights)
    assert all(np.array_equal(a, b) for a, b in zip(before, after))
    with pytest.raises(WeightsError, match="not found"):
        infer.get_backend(weights, "torch")
