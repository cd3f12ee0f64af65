"""The AFF grid head as a weighted gather: r' for a block of the MERL grid in ~3 memory passes.

Per grid point u the head of :class:`~specgen_addon.model.runtime.fast.GridHead` computes (Eq. 8–11, then
the MLP with its first layer folded into the tables)::

    w = softmax(z(s)),   s = Σ_k s_k + b            (z: the AFF logits, piecewise linear in s)
    h = ReLU(Σ_k w_k (W1 f_k) + b1)
    r' = w3 · ReLU(W2 h + b2) + b3

In eager torch every term of ``Σ_k w_k W1 f_k`` is a broadcast pass over a (points × h1) temporary,
which makes the head memory-bound. Here the sum is one :func:`torch.nn.functional.embedding_bag`
(a gather of six table rows per point, weighted by ``w_k``: one pass, no temporaries), and four
exact rewrites remove the remaining passes or shrink them:

* **softmax without a max pass.** ``z_k(s) − max_m z_m(s)`` is itself piecewise linear in ``s``:
  the AFF kinks are refined at the crossings where the arg-max branch changes, so one
  ``bucketize`` + one row gather give the shifted logits, and ``e_k = exp(…) ≤ 1`` cannot overflow.
* **normalisation at the end.** The gather uses the unnormalised ``e_k``. Each table row carries
  ``W1 f_k + b1`` and a trailing 1, so the gathered row is ``[t·(h_pre), t]`` with ``t = Σ e_k``;
  ``t`` rides through the ReLUs (it is positive) and the second layer (as the bias column
  ``[W2 | b2]``), and ``r' = w3·g / t + b3`` divides once per point, not once per channel.
* **dead first-layer units dropped.** ``h`` is a convex combination of six table rows, so a unit
  whose entries are ≤ 0 in every row of this image's tables is ≤ 0 everywhere and its ReLU is 0:
  its column of the row table and its row of ``[W2 | b2]`` are dropped (7 of 32 for one trained network on
  ``examples/sphere.png``).
* **θh rows at the end of the row table.** Rows that depend on θh (t1, t2, t4) sit after the
  fixed rows (t3, t5, t6) in a per-thread buffer, so a point's six row indices are fixed sums of
  its (θd, φd, λ) indices (built once per grid for the torch ops, computed inside the numba loop).
* **only the lookup's reach.** About a fifth of the grid lies so far below the horizon that no
  lookup touches it (:mod:`specgen_addon.brdf.lookup_reach`): each block computes, in every θd row, only
  the run of φd nodes that can be read, and leaves the rest to the caller.

With numba installed (the command line's requirements), the logits, the gather with its ReLU and
the output layer run as three compiled loops (:mod:`specgen_addon.model.runtime.gather_kernels`), about
1.2–1.6× faster over the grid (lab/notebook/model-reference.md); ``SPECGEN_KERNELS=torch`` keeps the
torch ops.

Same output as :class:`~specgen_addon.model.runtime.fast.GridHead` to float rounding (tests/model/test_infer.py).
"""

from __future__ import annotations

import math
import threading
from itertools import pairwise

import numpy as np
import torch
import torch.nn.functional as F

from specgen_addon.brdf.lookup_reach import phi_d_reach
from specgen_addon.brdf.table import N_PHI_D, N_THETA_D
from specgen_addon.model.runtime import gather_kernels


@torch.no_grad()
def shifted_logit_segments(fusion) -> tuple[torch.Tensor, torch.Tensor]:
    """Kinks ``(n,)`` and per-segment rows ``[P | Q]`` ``(n + 1, 12)``:
    ``z_k(s) − max_m z_m(s) = P_k s + Q_k`` on each segment.

    ``z(s) = β · ReLU(a s + c) + β_b`` (Eq. 8–10) is linear between the kinks ``−c_i / a_i``;
    inside each such interval the segments are cut again where the arg-max branch changes, so
    the arg-max row of every segment is exactly zero. Segment ``r`` covers ``(kinks[r−1], kinks[r]]``
    (:func:`torch.bucketize`); the forms agree at every cut, so the side a tie falls on is immaterial.
    """
    a = fusion.expand.weight[:, 0].double()
    c = fusion.expand.bias.double()
    beta, beta_b = fusion.heads.weight.double(), fusion.heads.bias.double()
    nz = a != 0
    edges = [-np.inf] + sorted(set((-c[nz] / a[nz]).tolist())) + [np.inf]

    def inside(lo: float, hi: float) -> float:
        if np.isfinite(lo) and np.isfinite(hi):
            return (lo + hi) / 2
        return hi - 1.0 if np.isfinite(hi) else (lo + 1.0 if np.isfinite(lo) else 0.0)

    kinks: list[float] = []
    rows: list[torch.Tensor] = []
    for lo, hi in pairwise(edges):
        active = ((a * inside(lo, hi) + c) > 0).double()
        p, q = beta @ (active * a), beta @ (active * c) + beta_b            # z_k = p_k s + q_k here
        cuts = []
        for k in range(p.numel()):
            for m in range(k + 1, p.numel()):
                dp = float(p[k] - p[m])
                cut = float(q[m] - q[k]) / dp if dp != 0.0 else lo               # z_k = z_m here
                if lo < cut < hi:
                    cuts.append(cut)
        points = [lo] + sorted(cuts) + [hi]
        for u0, u1 in pairwise(points):
            top = int(torch.argmax(p * inside(u0, u1) + q))
            row = torch.cat([p - p[top], q - q[top]])
            if rows and torch.equal(row, rows[-1]):
                continue                                                    # same form: merge
            if rows:
                kinks.append(u0)
            rows.append(row)
    return torch.tensor(kinks, dtype=torch.float32), torch.stack(rows).float().contiguous()


def decode_inplace(rp: np.ndarray, mu: float) -> None:
    """:func:`specgen_addon.brdf.table.mu_law_decode_inplace` (clip at 0, inverse μ-law) on torch's
    vectorised ``expm1``: about 3× numpy's, the same values to float rounding."""
    x = torch.from_numpy(rp)
    x.clamp_(min=0.0).mul_(math.log1p(mu)).expm1_().div_(mu)


class GatherGridHead:
    """r' on the full grid for one image's six tables (AFF only), block by block, thread-safe.

    ``tables``: the six :class:`~specgen_addon.model.runtime.fast.GridTables` outputs ``(…, h1 + 1)``
    (``W1·f`` and the AFF statistic); ``n_theta_d``: θd rows per block. :meth:`block` returns
    r' ``(1, nd, 180, Λ)`` for θh row ``i`` and θd rows ``j … j + nd``.
    """

    def __init__(self, model, tables, n_theta_d: int):
        fusion, mapping = model.fusion, model.mapping
        self.kinks, self.pq = shifted_logit_segments(fusion)
        _, bias = fusion.gap_functionals()
        with torch.no_grad():
            self.bias = bias.detach().clone()
            self.w2_t = torch.cat([mapping.fc2.weight, mapping.fc2.bias[:, None]], 1).T.contiguous()
            self.w3 = mapping.fc3.weight[0].detach().contiguous()
            self.b3 = float(mapping.fc3.bias)
            t1, t2, t3, t4, t5, t6 = tables
            self.stat = tuple(t[..., -1].contiguous() for t in tables)
            b1 = mapping.fc1.bias

            def rows(t: torch.Tensor) -> torch.Tensor:                  # [W1 f + b1, 1]
                return torch.cat([t[..., :-1] + b1, torch.ones(t.shape[:-1] + (1,))], -1)

            theta_h_rows = (rows(t1), rows(t2), rows(t4))                # (90, ·, h1 + 1) each
            fixed = torch.cat([rows(t3).flatten(0, 1), rows(t5).flatten(0, 1), rows(t6).flatten(0, 1)])
            # A unit of the first layer whose rows are ≤ 0 in every table is ≤ 0 at every grid point
            # (h is a convex combination of six rows), so its ReLU is 0 there: drop it, exactly.
            top = torch.stack([fixed.amax(0)] + [t.amax((0, 1)) for t in theta_h_rows]).amax(0)
            keep = torch.nonzero(top > 0).flatten()                       # the trailing 1 is kept
            self.units_dropped = int(top.numel() - keep.numel())
            self.theta_h_rows = tuple(t[..., keep].contiguous() for t in theta_h_rows)
            self.fixed = fixed[:, keep].contiguous()
            self.w2_t = self.w2_t[keep].contiguous()
        n_l = t4.shape[1]
        self.n_lambda, self.nd = n_l, n_theta_d
        self.lo, self.hi = (np.array(a, dtype=np.int64) for a in phi_d_reach())
        o3, o5 = 0, N_THETA_D * N_PHI_D                                  # fixed rows: t3 | t5 | t6
        o6 = o5 + N_THETA_D * n_l
        o1 = self.fixed.shape[0]                                          # then t1[i] | t2[i] | t4[i]
        o2, o4 = o1 + N_THETA_D, o1 + N_THETA_D + N_PHI_D
        self.offsets = np.array([o1, o2, o3, o4, o5, o6], dtype=np.int64)
        self._local = threading.local()

        self.kernels = gather_kernels.load()            # numba loops for three stretches, or None
        if self.kernels is not None:                     # their arguments, as numpy arrays, once
            self._stat_np = tuple(t.numpy() for t in self.stat)
            self._bias_np = np.float32(float(self.bias))
            self._kinks_np, self._pq_np = self.kinks.numpy(), self.pq.numpy()
            self._w3_np, self._b3_np = self.w3.numpy(), np.float32(self.b3)
            return                                       # the loops compute the rows' indices
        self.indices = {}                                # torch ops: each block's (P, 6) row indices
        for j in range(0, N_THETA_D, n_theta_d):
            nd = min(n_theta_d, N_THETA_D - j)
            d, p, lam = torch.meshgrid(torch.arange(j, j + nd), torch.arange(N_PHI_D), torch.arange(n_l),
                                       indexing="ij")
            self.indices[j] = torch.stack([o1 + d, o2 + p, o3 + d * N_PHI_D + p, o4 + lam, o5 + d * n_l + lam,
                                           o6 + p * n_l + lam], -1).reshape(-1, 6).int().contiguous()

    def _row_table(self, i: int) -> torch.Tensor:
        """This thread's row table with θh row ``i``'s rows at its end."""
        local = self._local
        if getattr(local, "rows", None) is None:
            n_h = sum(t.shape[1] for t in self.theta_h_rows)
            local.rows = torch.cat([self.fixed, torch.empty(n_h, self.fixed.shape[1])])
            local.i = None
        if local.i != i:
            torch.cat([t[i] for t in self.theta_h_rows], out=local.rows[self.fixed.shape[0]:])
            local.i = i
        return local.rows

    def reach(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The φd nodes ``lo[r] … hi[r]`` a lookup can touch in θh row ``i``, θd rows ``j + r``
        (:func:`specgen_addon.brdf.lookup_reach.phi_d_reach`); only these are computed."""
        nd = min(self.nd, N_THETA_D - j)
        return self.lo[i, j:j + nd], self.hi[i, j:j + nd]

    @torch.no_grad()
    def block(self, i: int, j: int, decode_mu: float | None = None) -> np.ndarray:
        """r' ``(1, nd, 180, Λ)`` for θh row ``i``, θd rows ``j … j + nd`` (``f_r`` in sr⁻¹ with
        ``decode_mu``), at the φd nodes of :meth:`reach`; the other φd nodes of each row are left
        unspecified (no lookup reads them: :func:`specgen_addon.brdf.lookup_reach.extend_beyond_reach`
        fills them)."""
        if self.kernels is not None:
            r = self._block_kernels(i, j)
        else:
            r = self._block_torch(i, j)
        if decode_mu is not None:
            decode_inplace(r, decode_mu)
        lo, hi = self.reach(i, j)
        out = np.empty((1, lo.size, N_PHI_D, self.n_lambda), dtype=np.float32)
        start = 0
        for row, (a, b) in enumerate(zip(lo.tolist(), hi.tolist())):
            stop = start + (b + 1 - a) * self.n_lambda
            out[0, row, a:b + 1] = r[start:stop].reshape(-1, self.n_lambda)
            start = stop
        return out

    def _block_torch(self, i: int, j: int) -> np.ndarray:
        """r' at the reached points of a block (in (θd, φd, λ) order) on torch ops alone."""
        nd = min(self.nd, N_THETA_D - j)
        lo, hi = (torch.from_numpy(a) for a in self.reach(i, j))
        phi = torch.arange(N_PHI_D)
        reached = ((phi >= lo[:, None]) & (phi <= hi[:, None]))[:, :, None].expand(-1, -1, self.n_lambda)
        reached = reached.reshape(-1)
        s1, s2, s3, s4, s5, s6 = self.stat
        s_dp = s3[j:j + nd] + s2[i][None, :] + s1[i, j:j + nd][:, None]          # (nd, φd)
        s_dl = s5[j:j + nd] + (s4[i] + self.bias)[None, :]                         # (nd, Λ)
        s = (s_dp[:, :, None] + s_dl[:, None, :] + s6[None]).reshape(-1)[reached]
        pq = self.pq.index_select(0, torch.bucketize(s, self.kinks))
        e = torch.addcmul(pq[:, 6:], pq[:, :6], s[:, None]).exp_()              # (P, 6), ≤ 1
        h = F.embedding_bag(self.indices[j][reached], self._row_table(i), per_sample_weights=e, mode="sum")
        h.relu_()                                                                # [t·h_pre, t]
        g = torch.mm(h, self.w2_t).relu_()                                       # t · ReLU(W2 h + b2)
        return torch.mv(g, self.w3).div_(h[:, -1]).add_(self.b3).numpy()

    def _block_kernels(self, i: int, j: int) -> np.ndarray:
        """:meth:`_block_torch` with the logits, the gather and the output layer as numba loops
        (:mod:`specgen_addon.model.runtime.gather_kernels`); ``exp`` and the matrix product in torch."""
        nd = min(self.nd, N_THETA_D - j)
        lo, hi = self.reach(i, j)
        n_points = int((hi - lo + 1).sum()) * self.n_lambda
        e = np.empty((n_points, 6), dtype=np.float32)
        self.kernels.shifted_logits(i, j, nd, lo, hi, *self._stat_np, self._bias_np, self._kinks_np,
                                    self._pq_np, e)
        torch.from_numpy(e).exp_()
        rows = self._row_table(i)
        h = np.empty((n_points, rows.shape[1]), dtype=np.float32)
        t = np.empty(n_points, dtype=np.float32)
        self.kernels.gather_relu(j, nd, lo, hi, N_PHI_D, self.n_lambda, self.offsets, rows.numpy(), e, h, t)
        g = torch.mm(torch.from_numpy(h), self.w2_t)                             # t · (W2 h + b2)
        r = np.empty(n_points, dtype=np.float32)
        self.kernels.mlp_output(g.numpy(), t, self._w3_np, self._b3_np, r)
        return r
