"""Inference: one sphere image -> the full tabulated spectral BRDF (90 × 90 × 180 × Λ).

:func:`generate_brdf` is the entry point used by the CLI and the Blender add-on. Two backends run
the same computation (:mod:`specgen_addon.model.runtime.fast`): ``"torch"`` and ``"onnx"`` (onnxruntime,
for a stock Blender without torch); torch runs the AFF head as a weighted gather
(:mod:`specgen_addon.model.runtime.gather`, same output to float rounding, about half the memory passes),
three stretches of it as numba loops where numba is installed. Both compute only the nodes a
lookup above the horizon can touch (:mod:`specgen_addon.brdf.lookup_reach`, 78.5 % of the grid).
The grid is filled in blocks of θh × θd rows so memory stays bounded (a few tens of MB besides the
output), two blocks at a time on two worker threads.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from specgen_addon.common.errors import Cancelled, SpecGenError, WeightsError
from specgen_addon.brdf.lookup_reach import extend_beyond_reach, phi_d_reach
from specgen_addon.photo.resample import resample_square
from specgen_addon.spectral.spectra import DEFAULT_WAVELENGTHS_NM
from specgen_addon.brdf.table import GRID_SHAPE, N_PHI_D, N_THETA_D, N_THETA_H, BRDFTable, mu_law_decode_inplace
from specgen_addon.common.limits import bad_values
from specgen_addon.model.config import Config
from specgen_addon.model.shipped import DEFAULT_WEIGHTS, shipped_weights
from specgen_addon.model.checksums import verify
from specgen_addon.photo import sphere_image as input_image

if TYPE_CHECKING:
    from specgen_addon.photo.sphere_image import SphereCrop

BACKENDS = ("torch", "onnx")
#: θd rows per block: 10 × 180 × Λ points (~38 k at 21 bands) for torch's gather head (5–30 rows
#: time the same; fewer pay per-op overhead: 1 row is ~2× slower); the ONNX head, whose passes over
#: 32 × points temporaries dominate, ran best at 2 rows over all 180 φd nodes (7.6 k points: ~1 MB
#: temporaries, one core's L2) and at 4 rows since it runs only the lookup's reach (2 rows ~8 %
#: slower, 1 row ~25 %, 3, 5 and 6 rows within noise of 4 or slower; docs/blender.md). ``"onnx 180"``:
#: a head exported before the φd runs.
BLOCK_THETA_D = {"torch": 10, "onnx": 4, "onnx 180": 2}

ProgressFn = Callable[[float], None]
CancelFn = Callable[[], bool]


def network_input(image, image_size: int) -> np.ndarray:
    """Image (path, or array H×W×3/4 linear RGB) -> network input ``(1, 3, S, S)`` float32.

    Paths go through :func:`specgen_addon.photo.sphere_image.load_sphere_image` (finds and crops the
    sphere, rejects images without one); arrays are checked the same way.
    """
    return resample_square(sphere_crop(image).image, image_size)[None]


def sphere_crop(image) -> SphereCrop:
    """The canonical crop of an image (path, or array H×W×3/4 linear RGB), and how it was cut
    (:class:`specgen_addon.photo.sphere_image.SphereCrop`); a crop already made is returned as it is."""
    if isinstance(image, input_image.SphereCrop):
        return image
    if isinstance(image, input_image.PhotoSource):
        return image.crop()
    if isinstance(image, (str, Path)):
        return input_image.load_sphere_crop(image)
    return input_image.crop_sphere(np.asarray(image))


# ---------------------------------------------------------------------------------- backends
_MODEL_CACHE: dict[tuple, object] = {}
_LOCK = threading.Lock()


def _weights_path(weights) -> Path:
    return Path(weights) if weights is not None else DEFAULT_WEIGHTS


def onnx_paths(weights_pt: Path) -> tuple[Path, Path]:
    """The two ONNX graphs exported beside a ``.pt`` weights file: tables and head."""
    stem = weights_pt.with_suffix("")
    return Path(f"{stem}.tables.onnx"), Path(f"{stem}.head.onnx")


class _TorchBackend:
    def __init__(self, weights: Path):
        import torch

        from specgen_addon.model.specgen import load_weights
        from specgen_addon.model.runtime.fast import GridHead, GridTables

        self.torch = torch
        self.model = load_weights(weights)
        self.cfg = self.model.cfg
        self.tables = GridTables(self.model).eval()
        self.head = GridHead(self.model).eval()

    def make_tables(self, x: np.ndarray, u_lambda: np.ndarray) -> tuple[np.ndarray, ...]:
        with self.torch.no_grad():
            out = self.tables(self.torch.from_numpy(x), self.torch.from_numpy(u_lambda))
        return tuple(t.contiguous() for t in out)

    def prepare(self, tables, nd: int):
        """AFF: the gather head for these tables (:class:`~specgen_addon.model.runtime.gather.GatherGridHead`);
        Hadamard: the tables as they are."""
        if self.cfg.fusion != "aff":
            return tables
        from specgen_addon.model.runtime.gather import GatherGridHead

        return GatherGridHead(self.model, tables, nd)

    def run_block(self, prepared, i: int, j: int, nd: int, decode_mu: float | None = None) -> np.ndarray:
        """r' ``(1, nd, 180, Λ)`` for θh row ``i`` and θd rows ``j … j+nd`` (``f_r`` with
        ``decode_mu``); entries beyond the lookup's reach may be left unspecified."""
        if not isinstance(prepared, tuple):
            return prepared.block(i, j, decode_mu)
        with self.torch.no_grad():
            r = self.head(*table_block(prepared, i, j, nd)).numpy()
        if decode_mu is not None:
            from specgen_addon.model.runtime.gather import decode_inplace

            decode_inplace(r, decode_mu)
        return r


class _OnnxBackend:
    def __init__(self, weights: Path):
        try:
            import onnxruntime as ort
        except ImportError as exc:  # pragma: no cover - listed in requirements / manifest wheels
            raise SpecGenError("the onnx backend needs the onnxruntime package") from exc
        import json

        tables_path, head_path = onnx_paths(weights)

        for p in (tables_path, head_path):
            if not p.is_file():
                raise WeightsError(f"{p}: ONNX graph not found (run `python -m specgen_addon export-onnx`)")
            verify(p)  # a damaged shipped graph is refused, not silently replaced by another backend
        # Parallel over blocks (evaluate_grid's two worker threads share the session, whose run()
        # is thread-safe): one thread per run, no intra-op pool to spin or synchronise; full graph
        # optimisation (MatMul+Add+Relu fusions). A session per worker measured the same.
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        try:
            self.tables = ort.InferenceSession(str(tables_path), opts, providers=["CPUExecutionProvider"])
            self.head = ort.InferenceSession(str(head_path), opts, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise WeightsError(f"{tables_path.parent}: unreadable ONNX graph ({type(exc).__name__})") from None
        names = tuple(i.name for i in self.head.get_inputs())
        if names not in HEAD_LAYOUTS:
            raise WeightsError(f"{head_path}: not a SpecGen head graph (inputs {', '.join(names)}); "
                               "run `python -m specgen_addon export-onnx --overwrite`")
        #: "low_rank" (the current export), "channels_first" (earlier exports) or "plain" (Hadamard)
        self.head_layout = HEAD_LAYOUTS[names]
        self._inputs = names
        #: whether the head takes a run of φd nodes (current exports) or
        #: all 180 (earlier ones): then only the lookup's reach is computed
        self.phi_d_runs = self.head_layout == "low_rank" and not isinstance(
            self.head.get_inputs()[names.index("f2")].shape[3], int)
        meta = self.tables.get_modelmeta().custom_metadata_map
        try:
            self.cfg = Config.from_dict(json.loads(meta["specgen_config"]))
        except Exception:
            raise WeightsError(f"{tables_path}: ONNX graph carries no SpecGen config") from None

    def make_tables(self, x: np.ndarray, u_lambda: np.ndarray) -> tuple[np.ndarray, ...]:
        return tuple(self.tables.run(None, {"image": x, "u_lambda": u_lambda}))

    def prepare(self, tables, nd: int):
        return _ARRANGE[self.head_layout](tables)

    def run_block(self, prepared, i: int, j: int, nd: int, decode_mu: float | None = None) -> np.ndarray:
        """As :meth:`_TorchBackend.run_block`; a head that takes a run of φd nodes computes only
        the run that holds the block's reach (:func:`specgen_addon.brdf.lookup_reach.phi_d_reach`)."""
        if not self.phi_d_runs:
            r = np.ascontiguousarray(self.run_head(_CUT[self.head_layout](prepared, i, j, nd)))
            run = r
        else:
            lo, hi = (a[i, j:j + nd] for a in phi_d_reach())
            phi_d = slice(int(lo.min()), int(hi.max()) + 1)
            part = self.run_head(low_rank_block(prepared, i, j, nd, phi_d))
            r = np.empty(part.shape[:2] + (N_PHI_D,) + part.shape[3:], dtype=np.float32)
            run = r[:, :, phi_d]
            run[...] = part
        if decode_mu is not None:
            mu_law_decode_inplace(run, decode_mu)
        return r

    def run_head(self, blocks) -> np.ndarray:
        r = self.head.run(None, {n: np.ascontiguousarray(b) for n, b in zip(self._inputs, blocks)})[0]
        if self.head_layout == "plain":
            return r
        return r.transpose(1, 2, 3, 0)                        # (Λ, nh, nd, φd) -> (nh, nd, φd, Λ)


CHANNELS_FIRST_INPUTS = ("s1", "s2", "s3", "s4", "s5", "s6", "f1", "f2", "f3", "f4", "f5", "f6")
LOW_RANK_INPUTS = ("s1", "s2", "s3", "s4", "s5", "s6", "low", "f2", "f3", "f6", "eye")
PLAIN_INPUTS = ("t1", "t2", "t3", "t4", "t5", "t6")
#: The head graphs the onnx backend runs, by their input names.
HEAD_LAYOUTS = {LOW_RANK_INPUTS: "low_rank", CHANNELS_FIRST_INPUTS: "channels_first", PLAIN_INPUTS: "plain"}


def table_block(tables, i: int, j: int, nd: int) -> tuple:
    """Rows of the six grid tables for θh row ``i`` and θd rows ``j … j+nd`` (:class:`GridHead` inputs)."""
    t1, t2, t3, t4, t5, t6 = tables
    si, sj = slice(i, i + 1), slice(j, j + nd)
    return t1[si, sj], t2[si], t3[sj], t4[si], t5[sj], t6


def channels_first_tables(tables, features: bool = True) -> tuple[np.ndarray, ...]:
    """The six grid tables (…, C+1) arranged once for the channels-first head of earlier exports
    (:class:`~specgen_addon.model.runtime.fast.GridHeadChannelsFirst`): statistic rows ``s_k``
    (Λ|1, 90|1, 90|1, 180|1) and, with ``features``, feature rows ``f_k`` (C, Λ|1, 90|1, 90|1, 180|1)."""
    t1, t2, t3, t4, t5, t6 = (np.asarray(t, dtype=np.float32) for t in tables)
    cf = (t1.transpose(2, 0, 1)[:, None, :, :, None], t2.transpose(2, 0, 1)[:, None, :, None, :],
          t3.transpose(2, 0, 1)[:, None, None, :, :], t4.transpose(2, 1, 0)[:, :, :, None, None],
          t5.transpose(2, 1, 0)[:, :, None, :, None], t6.transpose(2, 1, 0)[:, :, None, None, :])
    stats = tuple(np.ascontiguousarray(a[-1]) for a in cf)
    return stats + tuple(np.ascontiguousarray(a[:-1]) for a in cf) if features else stats


@dataclass(frozen=True)
class LowRankTables:
    """The six grid tables arranged once for the low-rank head
    (:class:`~specgen_addon.model.runtime.fast.GridHeadLowRank`): the statistic rows ``s_k`` of
    :func:`channels_first_tables`, and the features ``f1 (90, 90, C)``, ``f4 (90, Λ, C)``,
    ``f5 (90, Λ, C)`` as they are, ``f2 (90, C, 180)``, ``f3 (C, 90, 180)`` and
    ``f6 (Λ, C, 1, 180)`` with the channels ahead of φd."""

    stats: tuple[np.ndarray, ...]
    f1: np.ndarray
    f2: np.ndarray
    f3: np.ndarray
    f4: np.ndarray
    f5: np.ndarray
    f6: np.ndarray


def low_rank_tables(tables) -> LowRankTables:
    """The six grid tables (…, C+1) arranged once per grid for :func:`low_rank_block`."""
    t1, t2, t3, t4, t5, t6 = (np.asarray(t, dtype=np.float32) for t in tables)
    c = t1.shape[-1] - 1
    return LowRankTables(
        stats=channels_first_tables(tables, features=False),
        f1=np.ascontiguousarray(t1[..., :c]), f4=np.ascontiguousarray(t4[..., :c]),
        f5=np.ascontiguousarray(t5[..., :c]),
        f2=np.ascontiguousarray(t2[..., :c].transpose(0, 2, 1)),
        f3=np.ascontiguousarray(t3[..., :c].transpose(2, 0, 1)),
        f6=np.ascontiguousarray(t6[..., :c].transpose(1, 2, 0)[:, :, None, :]))


def low_rank_block(arranged: LowRankTables, i: int, j: int, nd: int,
                   phi_d: slice = slice(None)) -> tuple[np.ndarray, ...]:
    """The low-rank head's inputs (:data:`LOW_RANK_INPUTS`) for θh row ``i``, θd rows
    ``j … j+nd`` and the φd nodes ``phi_d`` (all by default; a run needs a head exported with a
    free φd axis)."""
    nd = min(nd, arranged.f1.shape[1] - j)
    f1, f4, f5 = arranged.f1[i, j:j + nd], arranged.f4[i], arranged.f5[j:j + nd]   # (nd, C), (Λ, C), (nd, Λ, C)
    n_l, c = f4.shape
    low = np.empty((n_l, c, 2 * nd + 1), dtype=np.float32)
    low[:, :, :nd] = f1.T[None]
    low[:, :, nd] = f4
    low[:, :, nd + 1:] = f5.transpose(1, 2, 0)
    stats = tuple(a[..., phi_d] if a.shape[-1] > 1 else a for a in channels_first_block(arranged.stats, i, j, nd))
    return (*stats, low, arranged.f2[i][None, :, None, phi_d], arranged.f3[None, :, j:j + nd, phi_d],
            arranged.f6[..., phi_d], np.eye(nd, dtype=np.float32))


def channels_first_block(arranged, i: int, j: int, nd: int) -> tuple[np.ndarray, ...]:
    """:func:`channels_first_tables` cut to θh row ``i`` and θd rows ``j … j+nd`` (axes −3, −2)."""
    def cut(a: np.ndarray) -> np.ndarray:
        return a[..., slice(i, i + 1) if a.shape[-3] > 1 else slice(None),
                 slice(j, j + nd) if a.shape[-2] > 1 else slice(None), :]

    return tuple(cut(a) for a in arranged)


#: Per head layout: how the six grid tables are arranged once per grid, and cut per block.
_ARRANGE = {"low_rank": low_rank_tables, "channels_first": channels_first_tables, "plain": lambda tables: tables}
_CUT = {"low_rank": low_rank_block, "channels_first": channels_first_block, "plain": table_block}


def get_backend(weights=None, backend: str = "torch"):
    """A (cached) backend for a weights file; raises :class:`WeightsError` for bad files."""
    if backend not in BACKENDS:
        raise SpecGenError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    path = _weights_path(weights)
    anchor = path
    if backend == "onnx" and not path.is_file() and onnx_paths(path)[0].is_file():
        anchor = onnx_paths(path)[0]  # the graphs stand alone: the extension ships no .pt (torch only)
    elif not path.is_file():
        raise WeightsError(f"{path}: weights file not found")
    key = (backend, str(anchor.resolve()), anchor.stat().st_mtime_ns)
    with _LOCK:
        if key not in _MODEL_CACHE:
            _MODEL_CACHE[key] = _TorchBackend(path) if backend == "torch" else _OnnxBackend(path)
        return _MODEL_CACHE[key]


# ---------------------------------------------------------------------------------- generation
def generate_brdf(image, weights=None, wavelengths_nm=None, backend: str = "torch",
                  progress: ProgressFn | None = None, cancel: CancelFn | None = None,
                  band_gap_nm: float | None = None) -> BRDFTable:
    """Generate the spectral BRDF of the material in ``image`` on the MERL grid.

    Parameters
    ----------
    image
        Path to an image of a material sphere (EXR/PNG/JPEG), an H×W×3/4 linear RGB array, or a
        :class:`~specgen_addon.photo.sphere_image.SphereCrop` already cut from one (not cut again).
    weights
        ``.pt`` weights file; ``None`` picks the shipped network for how the sphere was cut
        (:func:`specgen_addon.model.shipped_weights`: the default network for a sphere copied from a
        canonical frame, the resampled-input network for one resampled from a photo). The onnx
        backend uses the two graphs exported beside it (``<stem>.tables.onnx``, ``<stem>.head.onnx``).
    wavelengths_nm
        Band centres in nm inside the model's range (default: 380–780 nm, 21 bands).
    backend
        ``"torch"`` or ``"onnx"``.
    progress, cancel
        ``progress(fraction)`` after each block; ``cancel()`` returning True raises
        :class:`~specgen_addon.common.errors.Cancelled` (no table is returned).
    band_gap_nm
        ``None``: the network evaluates every band. A gap in nm: only the bands of
        :func:`network_bands` (neighbours at most this far apart), the others interpolated
        linearly in λ between them (:func:`fill_bands`); the table's metadata lists the
        network's bands.

    Returns
    -------
    BRDFTable
        ``f_r`` in sr⁻¹, shape (90, 90, 180, Λ), float32.
    """
    crop = sphere_crop(image)
    if weights is None:
        weights = shipped_weights(crop.copied)
    be = get_backend(weights, backend)
    cfg = be.cfg
    wl = np.asarray(DEFAULT_WAVELENGTHS_NM if wavelengths_nm is None else wavelengths_nm, dtype=np.float64)
    if wl.ndim != 1 or wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
        raise SpecGenError("wavelengths must be a non-empty increasing list (nm)")
    if wl[0] < cfg.lambda_min_nm - 1e-6 or wl[-1] > cfg.lambda_max_nm + 1e-6:
        raise SpecGenError(f"wavelengths {wl[0]:g}–{wl[-1]:g} nm fall outside the model's "
                           f"{cfg.lambda_min_nm:g}–{cfg.lambda_max_nm:g} nm")
    x = resample_square(crop.image, cfg.image_size)[None].astype(np.float32)
    kept = network_bands(wl, band_gap_nm)
    u_lambda = cfg.lambda_coordinates(wl[kept])
    tables = be.make_tables(x, u_lambda)
    values = evaluate_grid(be, tables, kept.size, progress=progress, cancel=cancel, decode_mu=cfg.mu)
    if kept.size < wl.size:
        values = fill_bands(values, wl, kept)

    reason = bad_values(values)
    if reason:
        raise WeightsError(f"{_weights_path(weights)}: the network produced {reason} "
                           "(broken weights?)")
    src = "image" if not isinstance(image, (str, Path)) else str(image)
    meta = {"source": "specgen", "input_image": src, "backend": backend,
            "weights": str(_weights_path(weights)), "input_sphere": "copied" if crop.copied else "resampled",
            "description": "SpecGen prediction"}
    if kept.size < wl.size:
        meta["network_bands_nm"] = [float(v) for v in wl[kept]]
    return BRDFTable(values, wl, metadata=meta)


def network_bands(wavelengths_nm: np.ndarray, max_gap_nm: float | None) -> np.ndarray:
    """Indices of the bands the network evaluates: all with ``max_gap_nm`` None; else the fewest
    bands, first and last included, whose neighbours are at most ``max_gap_nm`` apart (every other
    band of a 20 nm grid at 40 nm; every band of a grid already coarser than the gap)."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if max_gap_nm is None or wl.size <= 2:
        return np.arange(wl.size)
    kept = [0]
    for k in range(1, wl.size - 1):
        if wl[k + 1] - wl[kept[-1]] > max_gap_nm + 1e-9:   # skipping k would leave too wide a gap
            kept.append(k)
    kept.append(wl.size - 1)
    return np.asarray(kept)


def fill_bands(values: np.ndarray, wavelengths_nm: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """``values`` (…, len(kept)) at the bands ``kept`` of ``wavelengths_nm`` -> (…, Λ): each other
    band linearly interpolated in λ between its kept neighbours (``f_r`` itself, so an
    interpolated band is the same mix of the two measured radiances); one matrix product."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    nodes = wl[kept]
    mix = np.stack([np.interp(wl, nodes, e) for e in np.eye(kept.size)])   # (kept, Λ): hat functions
    flat = values.reshape(-1, kept.size)
    return (flat @ mix.astype(values.dtype)).reshape(values.shape[:-1] + (wl.size,))


def evaluate_grid(be, tables, n_lambda: int, progress: ProgressFn | None = None,
                  cancel: CancelFn | None = None, workers: int = 2,
                  decode_mu: float | None = None) -> np.ndarray:
    """r' (μ-law) on the full grid ``(90, 90, 180, Λ)``, block by block on ``workers`` threads;
    with ``decode_mu``, ``f_r`` (sr⁻¹) instead, each block decoded on its worker
    (:func:`specgen_addon.brdf.table.mu_law_decode_inplace`).

    Only the nodes an above-horizon lookup can touch are the network's
    (:func:`specgen_addon.brdf.lookup_reach.phi_d_reach`, 78.5 % of the grid; the torch gather head
    computes no others); every other φd node takes the value of the nearest reached node of its
    row, so no lookup, render or fit sees a difference."""
    nd = BLOCK_THETA_D["torch" if isinstance(be, _TorchBackend) else "onnx" if be.phi_d_runs else "onnx 180"]
    prepared = be.prepare(tables, nd)
    lo, hi = phi_d_reach()
    out = np.empty(GRID_SHAPE + (n_lambda,), dtype=np.float32)
    blocks = [(i, j) for i in range(N_THETA_H) for j in range(0, N_THETA_D, nd)]
    done = [0]
    lock = threading.Lock()
    stop = threading.Event()

    def work(ij: tuple[int, int]) -> None:
        if stop.is_set():
            return
        i, j = ij
        out[i:i + 1, j:j + nd] = be.run_block(prepared, i, j, nd, decode_mu)
        extend_beyond_reach(out[i, j:j + nd], lo[i, j:j + nd], hi[i, j:j + nd])
        with lock:
            done[0] += 1

    torch_threads = None
    if isinstance(be, _TorchBackend):
        torch_threads = be.torch.get_num_threads()
        be.torch.set_num_threads(1)   # parallel over blocks instead: no OpenMP barriers per op
    try:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            rows_per_tick = len(blocks) // N_THETA_H
            for start in range(0, len(blocks), rows_per_tick * 2):
                if cancel is not None and cancel():
                    stop.set()
                    raise Cancelled("BRDF generation cancelled")
                list(pool.map(work, blocks[start:start + rows_per_tick * 2]))
                if progress is not None:
                    progress(done[0] / len(blocks))
    finally:
        if torch_threads is not None:
            be.torch.set_num_threads(torch_threads)
    return out
