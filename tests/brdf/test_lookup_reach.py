"""The lookup's reach: every grid node an above-horizon lookup touches is reached, and no other."""

from __future__ import annotations

import numpy as np

from specgen_addon.brdf.lookup_reach import extend_beyond_reach, phi_d_reach, reached_fraction
from specgen_addon.brdf.rusinkiewicz import half_diff_from_io, io_from_half_diff
from specgen_addon.brdf.table import (N_PHI_D, BRDFTable, _linear_weights, grid_angles, phi_d_index,
                                 theta_d_index, theta_h_index)


def _above_horizon_pairs(rng, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Direction pairs above the horizon, many of them grazing (cos θ drawn as u³)."""
    def directions() -> np.ndarray:
        z = rng.uniform(0.0, 1.0, n) ** 3
        phi = rng.uniform(0.0, 2 * np.pi, n)
        s = np.sqrt(1 - z * z)
        return np.stack([s * np.cos(phi), s * np.sin(phi), z], 1)

    wi, wo = directions(), directions()
    keep = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    return wi[keep], wo[keep]


def _reached_mask() -> np.ndarray:
    lo, hi = phi_d_reach()
    p = np.arange(N_PHI_D)
    return (p >= lo[..., None]) & (p <= hi[..., None])


def test_every_node_a_lookup_above_the_horizon_touches_is_reached():
    """Brute force with the table's own index arithmetic (`BRDFTable.eval_hd`): all eight corners
    of each lookup, zero weights included."""
    lo, hi = phi_d_reach()
    rng = np.random.default_rng(0)
    touched = 0
    for _ in range(5):
        th, td, pd = half_diff_from_io(*_above_horizon_pairs(rng, 200_000))
        i0, i1, _ = _linear_weights(theta_h_index(th), 90, periodic=False)
        j0, j1, _ = _linear_weights(theta_d_index(td), 90, periodic=False)
        k0, k1, _ = _linear_weights(phi_d_index(pd), N_PHI_D, periodic=True)
        for a in (i0, i1):
            for b in (j0, j1):
                for c in (k0, k1):
                    assert np.all((c >= lo[a, b]) & (c <= hi[a, b]))
                    touched += c.size
    assert touched > 5_000_000


def test_pairs_on_the_edge_of_the_horizon_touch_only_reached_nodes():
    """(θh, θd, φd) drawn just inside |cos φd| = cot θh cot θd, where the reach is tightest."""
    rng = np.random.default_rng(1)
    th = rng.uniform(0.05, 1.55, 400_000)
    td = rng.uniform(0.05, 1.55, 400_000)
    bound = 1.0 / (np.tan(th) * np.tan(td))
    keep = bound < 1.0
    th, td, bound = th[keep], td[keep], bound[keep]
    pd = np.arccos(bound * (1.0 - rng.uniform(0.0, 1e-3, th.size))) * rng.choice([-1.0, 1.0], th.size)
    wi, wo = io_from_half_diff(th, td, pd)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert above.mean() > 0.99                                    # the analytic horizon, as the frames say
    values = np.where(_reached_mask(), 1.0, np.nan)[..., None]
    looked_up = BRDFTable(values.astype(np.float32)).eval_hd(*half_diff_from_io(wi[above], wo[above]))
    assert np.all(np.isfinite(looked_up))                         # no unreached node was read


def test_the_reach_is_one_run_about_ninety_degrees_holding_every_node_above_the_horizon():
    lo, hi = phi_d_reach()
    assert np.all(lo <= 90) and np.all(hi >= 90)
    th, td, pd = grid_angles()
    wi, wo = io_from_half_diff(th[:, None, None], td[None, :, None], pd[None, None, :])
    above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    assert np.all(_reached_mask()[above])
    assert 0.76 < above.mean() < reached_fraction() < 0.80       # a fifth of the grid is never read
    assert lo[0, 0] == 0 and hi[0, 0] == N_PHI_D - 1             # head-on: every φd is reached
    assert hi[89, 89] - lo[89, 89] < 5                           # grazing both ways: almost none


def test_unreached_nodes_take_the_nearest_reached_value_and_lookups_do_not_change():
    rng = np.random.default_rng(2)
    values = rng.uniform(0.0, 1.0, (90, 90, 180, 2)).astype(np.float32)
    filled = values.copy()
    lo, hi = phi_d_reach()
    extend_beyond_reach(filled, lo, hi)
    reached = _reached_mask()
    assert np.array_equal(filled[reached], values[reached])
    i, j = 89, 60
    assert np.all(filled[i, j, :lo[i, j]] == values[i, j, lo[i, j]])
    assert np.all(filled[i, j, hi[i, j] + 1:] == values[i, j, hi[i, j]])
    wi, wo = _above_horizon_pairs(rng, 100_000)
    assert np.array_equal(BRDFTable(values).eval(wi, wo), BRDFTable(filled).eval(wi, wo))
