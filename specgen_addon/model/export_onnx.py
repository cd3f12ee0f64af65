"""Export SpecGen to ONNX for onnxruntime (the Blender path needs no torch).

Two graphs, beside the ``.pt`` weights (see :func:`specgen_addon.infer.onnx_paths`):

* ``<stem>.tables.onnx``: ``image (1, 3, S, S)``, ``u_lambda (Λ,)`` -> the six grid tables
  (:class:`~specgen_addon.model.fast.GridTables`);
* ``<stem>.head.onnx``: a block of table rows -> r' (:class:`~specgen_addon.model.fast.GridHead`,
  exported in the channels-first arrangement of
  :class:`~specgen_addon.model.fast.GridHeadChannelsFirst`, which onnxruntime runs ~2× faster),
  with dynamic block sizes and band count.

The model config travels in the graphs' metadata (``specgen_config``), so the onnx backend does
not need the ``.pt`` file's pickle.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from ..io_utils import atomic_write
from .fast import GridHead, GridHeadChannelsFirst, GridTables, lambda_coords
from .specgen import SpecGen, load_weights

OPSET = 17


def _add_metadata(path: Path, cfg_json: str) -> None:
    import onnx

    model = onnx.load(str(path))
    entry = model.metadata_props.add()
    entry.key, entry.value = "specgen_config", cfg_json
    onnx.save(model, str(path))


def export_onnx(weights: str | Path | None = None, out_stem: str | Path | None = None,
                overwrite: bool = True) -> tuple[Path, Path]:
    """Export the tables and head graphs of a weights file; returns their paths."""
    from ..infer import CHANNELS_FIRST_INPUTS, channels_first_block, channels_first_tables, onnx_paths
    from ..spectra import DEFAULT_WAVELENGTHS_NM

    model = load_weights(weights)
    src = Path(weights) if weights is not None else None
    if out_stem is None:
        from .specgen import DEFAULT_WEIGHTS

        out_stem = (src or DEFAULT_WEIGHTS).with_suffix("")
    tables_path, head_path = onnx_paths(Path(f"{out_stem}.pt"))
    cfg_json = json.dumps(model.cfg.to_dict())
    aff = model.cfg.fusion == "aff"
    tables = GridTables(model).eval()
    head = (GridHeadChannelsFirst if aff else GridHead)(model).eval()
    image = torch.zeros(1, 3, model.cfg.image_size, model.cfg.image_size)
    u_lam = lambda_coords(model, DEFAULT_WAVELENGTHS_NM)
    with torch.no_grad():
        t = tables(image, u_lam)
    nd = 5
    if aff:  # channels-first arrangement, inputs cut from the once-arranged tables
        arranged = channels_first_tables([x.numpy() for x in t])
        blocks = tuple(torch.from_numpy(np.ascontiguousarray(b)) for b in channels_first_block(arranged, 0, 0, nd))
        names = CHANNELS_FIRST_INPUTS
        # axes (C,) Λ, nh, nd, φd: which of them vary with the block or the band count
        varying = ({"nh": 1, "nd": 2}, {"nh": 1}, {"nd": 2}, {"nl": 0, "nh": 1}, {"nl": 0, "nd": 2}, {"nl": 0})
        dyn_head = {n: {axis + (1 if n.startswith("f") else 0): name
                        for name, axis in varying[k % 6].items()} for k, n in enumerate(names)}
        dyn_head["r"] = {0: "nl", 1: "nh", 2: "nd"}
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
            _add_metadata(tmp, cfg_json)
    return tables_path, head_path


