"""The numba loops of :mod:`specgen_addon.model.runtime.gather_kernels` (see there), compiled on first call.

Loaded only by :func:`specgen_addon.model.runtime.gather_kernels.load`, from this file, under the one module
name :data:`~specgen_addon.model.runtime.gather_kernels.LOOPS_MODULE` whatever package holds it (the command
line's ``specgen_addon``, or the repository loaded as an add-on package): numba's on-disk cache
records the module name of each function it compiles and imports it when loading, so a cache
written under one package name must be readable under the other.
"""

import numba
import numpy as np

# fastmath without "nnan"/"ninf": a NaN from broken weights must reach `limits.bad_values` as a NaN
jit = numba.njit(nogil=True, fastmath={"reassoc", "contract", "nsz"}, cache=True)


@jit
def shifted_logits(i, j, nd, lo, hi, s1, s2, s3, s4, s5, s6, bias, kinks, pq, out):
    """``out[n, k] = P_k s + Q_k`` (AFF logits minus their maximum) for θh row ``i``, θd rows
    ``d = j … j + nd`` and, in each, the φd nodes ``lo[d − j] … hi[d − j]`` (the lookup's reach),
    points in (θd, φd, λ) order; ``s = s1[i,d] + s2[i,p] + s3[d,p] + s4[i,l] + bias + s5[d,l]
    + s6[p,l]``; the segment is the count of kinks below ``s``, as ``torch.bucketize``."""
    n_l = s4.shape[1]
    n_k = kinks.shape[0]
    top = 1
    while top * 2 <= n_k:
        top *= 2
    n = 0
    for r in range(nd):
        d = j + r
        for p in range(lo[r], hi[r] + 1):
            s_dp = s1[i, d] + s2[i, p] + s3[d, p] + bias
            for lam in range(n_l):
                s = s_dp + s4[i, lam] + s5[d, lam] + s6[p, lam]
                seg = 0
                step = top
                while step > 0:
                    if seg + step <= n_k and kinks[seg + step - 1] < s:
                        seg += step
                    step >>= 1
                for k in range(6):                      # six branches: a constant trip count
                    out[n, k] = pq[seg, k] * s + pq[seg, 6 + k]
                n += 1


@jit
def gather_relu(j, nd, lo, hi, n_phi, n_l, offsets, rows, e, out, t):
    """``out[n] = ReLU(Σ_k e[n, k] · rows[index_k])``: the six-row weighted gather
    (``embedding_bag`` with per-sample weights) and the first layer's ReLU, one pass, over the
    points of :func:`shifted_logits` in its order. The six rows of point (θd row d, φd node p,
    band l) are ``offsets + (d, p, d·n_phi + p, l, d·n_l + l, p·n_l + l)``, ``offsets[k]``
    being where table ``t(k+1)``'s rows start in ``rows`` (t1[i], t2[i], t3, t4[i], t5, t6).
    ``t[n]`` is a copy of the last column (the softmax's ``Σ e``), contiguous for
    :func:`mlp_output`."""
    zero = np.float32(0.0)
    last = rows.shape[1] - 1
    o1, o2, o3, o4, o5, o6 = offsets[0], offsets[1], offsets[2], offsets[3], offsets[4], offsets[5]
    n = 0
    for r in range(nd):
        d = j + r
        for p in range(lo[r], hi[r] + 1):
            i0, i1, i2 = o1 + d, o2 + p, o3 + d * n_phi + p
            for lam in range(n_l):
                i3, i4, i5 = o4 + lam, o5 + d * n_l + lam, o6 + p * n_l + lam
                e0, e1, e2, e3, e4, e5 = e[n, 0], e[n, 1], e[n, 2], e[n, 3], e[n, 4], e[n, 5]
                for u in range(rows.shape[1]):
                    v = (e0 * rows[i0, u] + e1 * rows[i1, u] + e2 * rows[i2, u] + e3 * rows[i3, u]
                         + e4 * rows[i4, u] + e5 * rows[i5, u])
                    out[n, u] = zero if v <= zero else v    # ReLU that keeps a NaN, as torch's
                t[n] = out[n, last]
                n += 1


@jit
def mlp_output(g, t, w3, b3, out):
    """``out[n] = (w3 · ReLU(g[n])) / t[n] + b3``: the last layer, and the softmax's
    normalisation ``t`` (the trailing column of ``h``, contiguous) divided out once per point."""
    n_out = g.shape[1]
    zero = np.float32(0.0)
    for n in range(g.shape[0]):
        acc = zero
        for o in range(n_out):
            a = g[n, o]
            acc += w3[o] * (zero if a <= zero else a)
        out[n] = acc / t[n] + b3
