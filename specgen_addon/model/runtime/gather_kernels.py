"""Three compiled loops for :class:`~specgen_addon.model.runtime.gather.GatherGridHead` (numba, optional).

The gather head spends most of its time in three stretches of torch ops, each a pass or more over
a (points × k) temporary:

* the shifted AFF logits ``z_k(s) − max_m z_m(s) = P_k s + Q_k`` (building ``s`` from the six
  statistic tables, ``bucketize``, a row gather, ``addcmul``);
* the weighted six-row gather and the first layer's ReLU (``embedding_bag``, then a ReLU pass);
* the output ``r' = w3 · ReLU(g) / t + b3`` (a ReLU pass, a matrix-vector product, a division).

Here each is one loop over the points (numba, ``nogil``: the grid's worker threads run them side by
side). The ``exp`` and the second layer's matrix product stay in torch (its vectorised ``exp`` and
oneDNN's matrix product beat a plain loop). Same arithmetic in float32, summed in another order:
the values agree to float rounding (tests/model/test_infer.py).

numba is a requirement of the command line (requirements.txt), not of the Blender panel, whose
onnx backend never reaches this module. Without numba, or with ``SPECGEN_KERNELS=torch`` in the
environment, :func:`load` returns ``None`` and the head runs its torch ops. The loops themselves are
in ``_gather_loops.py``, loaded under one fixed module name (:data:`LOOPS_MODULE`) so numba's
on-disk cache serves both the command line and the repository loaded as an add-on package.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import threading
from pathlib import Path
from types import ModuleType

_LOCK = threading.Lock()

#: Set ``SPECGEN_KERNELS=torch`` to run the gather head on torch ops alone (for comparison).
ENV_VAR = "SPECGEN_KERNELS"
#: The module name the loops are loaded under, the same from every package that holds this file.
LOOPS_MODULE = "specgen_gather_loops"


def load() -> ModuleType | None:
    """The loops' module (``shifted_logits``, ``gather_relu``, ``mlp_output``), or ``None`` when
    numba is not installed or ``SPECGEN_KERNELS=torch``."""
    if os.environ.get(ENV_VAR, "").strip().lower() == "torch":
        return None
    with _LOCK:
        if LOOPS_MODULE not in sys.modules:
            if importlib.util.find_spec("numba") is None:
                return None
            path = Path(__file__).with_name("_gather_loops.py")
            spec = importlib.util.spec_from_file_location(LOOPS_MODULE, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[LOOPS_MODULE] = module        # before running it: numba's cache imports it by name
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[LOOPS_MODULE]
                raise
        return sys.modules[LOOPS_MODULE]
