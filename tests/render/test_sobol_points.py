"""The environment sampler's Sobol points: the stored table is scipy's own points, and the sampler
reads it before it asks scipy (:func:`specgen_addon.render.sampling._sobol`)."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.render import sampling


def test_the_stored_points_are_scipys_own():
    pytest.importorskip("scipy")
    table = sampling._sobol_table()
    assert len(table) == len(sampling.SOBOL_TABLE_COUNTS) * len(sampling.SOBOL_TABLE_SEEDS)
    for n in sampling.SOBOL_TABLE_COUNTS:
        for seed in sampling.SOBOL_TABLE_SEEDS:
            assert np.array_equal(table[f"n{n}_s{seed}"], sampling.sobol_scipy(n, seed)), (n, seed)


def test_stored_counts_never_reach_scipy_and_others_do(monkeypatch):
    """A Ctrl-C inside scipy's compiled Sobol set-up is swallowed there: the shipped settings'
    counts are read from the table, so a render never enters it."""
    calls = []

    def scipy_points(n, seed):
        calls.append((n, seed))
        return np.full((n, 2), 0.5)

    monkeypatch.setattr(sampling, "sobol_scipy", scipy_points)
    stored = sampling._sobol(16, 3)
    assert calls == [] and np.array_equal(stored, sampling._sobol_table()["n16_s3"])
    stored[0, 0] = -1.0                                        # a copy: the table is not changed
    assert sampling._sobol_table()["n16_s3"][0, 0] != -1.0
    assert np.array_equal(sampling._sobol(128, 3), np.full((128, 2), 0.5)) and calls == [(128, 3)]


def test_a_count_the_table_lacks_needs_scipy(monkeypatch):
    def no_scipy(n, seed):
        raise ImportError("No module named 'scipy'")

    monkeypatch.setattr(sampling, "sobol_scipy", no_scipy)
    with pytest.raises(SpecGenError, match="needs scipy"):
        sampling._sobol(128, 1)
