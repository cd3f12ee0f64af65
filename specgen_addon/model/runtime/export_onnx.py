"""Export SpecGen to ONNX for onnxruntime (the Blender path needs no torch).

Two graphs, beside the ``.pt`` weights (see :func:`specgen_addon.model.runtime.inference.onnx_paths`):

* ``<stem>.tables.onnx``: ``image (1, 3, S, S)``, ``u_lambda (Λ,)`` -> the six grid tables
  (:class:`~specgen_addon.model.runtime.fast.GridTables`);
* ``<stem>.head.onnx``: a block of table rows -> r' (:class:`~specgen_addon.model.runtime.fast.GridHead`,
  exported as :class:`~specgen_addon.model.runtime.fast.GridHeadLowRank`, which onnxruntime runs ~2.5×
  faster than the plain head; graphs exported earlier in the channels-first arrangement of
  :class:`~specgen_addon.model.runtime.fast.GridHeadChannelsFirst` still run), with dynamic block sizes,
  band count and run of φd nodes (current graphs: the backend computes only the
  φd nodes a lookup can touch, :mod:`specgen_addon.brdf.lookup_reach`; heads exported earlier take all
  180 and still run).

The model config travels in the graphs' metadata (``specgen_config``), so the onnx backend does
not need the ``.pt`` file's pickle.

Large weights that float16 holds exactly are stored as float16 and widened by a ``Cast`` at load
time (:func:`store_weights_half`): the shipped ``.pt`` holds float16 weights already, so the graph
computes with the same numbers in float32 at half the file size (two networks fit the repository's
40 MB and the extension's 60 MiB; docs/model-card.md, docs/blender.md).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from specgen_addon.common.atomic_io import atomic_write
from specgen_addon.model import checksums
from specgen_addon.model.runtime.fast import GridHead, GridHeadLowRank, GridTables, lambda_coords
from specgen_addon.model.specgen import load_weights
from specgen_addon.model.runtime.inference import LOW_RANK_INPUTS, low_rank_block, low_rank_tables, onnx_paths
from specgen_addon.model.specgen import DEFAULT_WEIGHTS
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM

OPSET = 17
#: Smaller initializers stay float32 (:func:`store_weights_half`): a Cast node would outweigh them.
HALF_MIN_ELEMENTS = 256


def store_weights_half(model, min_elements: int = HALF_MIN_ELEMENTS) -> int:
    """Store each float32 initializer of ``model`` (an ``onnx.ModelProto``) with at least
    ``min_elements`` elements that float16 holds exactly as float16, widened back to float32 by a
    ``Cast`` node at the head of the graph (onnxruntime folds it once when the session opens).
    Lossless: the graph computes with the same numbers. Returns how many it stored."""
    from onnx import TensorProto, helper, numpy_helper

    graph = model.graph
    casts, kept, n = [], [], 0
    for init in graph.initializer:
        if init.data_type != TensorProto.FLOAT or int(np.prod(init.dims)) < min_elements:
            kept.append(init)
            continue
        full = numpy_helper.to_array(init)
        narrow = full.astype(np.float16)
        if not np.array_equal(narrow.astype(np.float32), full):  # (float32 weights stay float32)
            kept.append(init)
            continue
        half = numpy_helper.from_array(narrow, f"{init.name}__f16")
        kept.append(half)
        casts.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT,
                                      name=f"{init.name}__widen"))
        n += 1
    del graph.initializer[:]
    graph.initializer.extend(kept)
    nodes = casts + list(graph.node)
    del graph.node[:]
    graph.node.extend(nodes)
    return n


def _finish_graph(path: Path, cfg_json: str, half: bool) -> None:
    """Add the model config to a graph's metadata and, with ``half``, store its weights as float16."""
    import onnx

    model = onnx.load(str(path))
    entry = model.metadata_props.add()
    entry.key, entry.value = "specgen_config", cfg_json
    if half:
        store_weights_half(model)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def export_onnx(weights: str | Path | None = None, out_stem: str | Path | None = None,
                overwrite: bool = True, half: bool = True) -> tuple[Path, Path]:
    """Export the tables and head graphs of a weights file; returns their paths.

    ``half`` stores the graphs' large weights as float16 where that is exact
    (:func:`store_weights_half`); computing stays float32."""
    model = load_weights(weights)
    src = Path(weights) if weights is not None else None
    if out_stem is None:
        out_stem = (src or DEFAULT_WEIGHTS).with_suffix("")
    tables_path, head_path = onnx_paths(Path(f"{out_stem}.pt"))
    cfg_json = json.dumps(model.cfg.to_dict())
    aff = model.cfg.fusion == "aff"
    tables = GridTables(model).eval()
    head = (GridHeadLowRank if aff else GridHead)(model).eval()
    image = torch.zeros(1, 3, model.cfg.image_size, model.cfg.image_size)
    u_lam = lambda_coords(model, DEFAULT_WAVELENGTHS_NM)
    with torch.no_grad():
        t = tables(image, u_lam)
    nd = 5
    if aff:  # the low-rank head's inputs, cut from the once-arranged tables
        arranged = low_rank_tables([x.numpy() for x in t])
        run = slice(30, 151)   # a run of φd nodes, not all 180: no size of the sample may become a constant
        blocks = tuple(torch.from_numpy(np.ascontiguousarray(b)) for b in low_rank_block(arranged, 0, 0, nd, run))
        names = LOW_RANK_INPUTS
        # which axes vary with the block's θd rows (nd), its run of φd nodes (np) or the band count (nl)
        dyn_head = {"s1": {2: "nd"}, "s2": {3: "np"}, "s3": {2: "nd", 3: "np"}, "s4": {0: "nl"},
                    "s5": {0: "nl", 2: "nd"}, "s6": {0: "nl", 3: "np"}, "low": {0: "nl", 2: "k"},
                    "f2": {3: "np"}, "f3": {2: "nd", 3: "np"}, "f6": {0: "nl", 3: "np"},
                    "eye": {0: "nd", 1: "nd"}, "r": {0: "nl", 2: "nd", 3: "np"}}
    else:
        blocks = (t[0][:1, :nd], t[1][:1], t[2][:nd], t[3][:1], t[4][:nd], t[5])
        names = ("t1", "t2", "t3", "t4", "t5", "t6")
        dyn_head = {"t1": {0: "nh", 1: "nd"}, "t2": {0: "nh"}, "t3": {0: "nd"}, "t4": {0: "nh", 1: "nl"},
                    "t5": {0: "nd", 1: "nl"}, "t6": {1: "nl"}, "r": {0: "nh", 1: "nd", 3: "nl"}}
    out_names = ("d1", "d2", "d3", "e1", "e2", "e3")
    dyn_tables = {"u_lambda": {0: "nl"}, "e1": {1: "nl"}, "e2": {1: "nl"}, "e3": {1: "nl"}}
    for path, module, args, in_names, outs, dyn in (
            (tables_path, tables, (image, u_lam), ("image", "u_lambda"), out_names, dyn_tables),
            (head_path, head, blocks, names, ("r",), dyn_head)):
        with atomic_write(path, overwrite=overwrite) as tmp:
            with torch.no_grad():
                torch.onnx.export(module, args, str(tmp), input_names=list(in_names),
                                  output_names=list(outs), dynamic_axes=dyn, opset_version=OPSET,
                                  dynamo=False)
            _finish_graph(tmp, cfg_json, half)
        checksums.record(path)  # the shipped folder's SHA256SUMS follows a re-export
    return tables_path, head_path


