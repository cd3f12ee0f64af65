"""Recolouring training materials per step: the affine reflectance, exact inputs, the draws."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from specgen_addon.corpus.material import Reflectance
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM
from specgen_addon.common.errors import SpecGenError
from specgen_addon.train import recolour as rc
from specgen_addon.train.data import TrainingMaterial
from specgen_addon.train.loop import MaterialSet, TrainConfig, _draw, make_step_batches


@functools.lru_cache(maxsize=1)
def _corpus():
    from specgen_addon.corpus.generate import generate_mixed_corpus, material_family

    corpus = [m for m in generate_mixed_corpus(120, seed=0) if m.split == "train"]
    by_family: dict[str, list] = {}
    for m in corpus:
        by_family.setdefault(material_family(m), []).append(m)
    return corpus, by_family


def test_the_swapped_reflectance_is_one_the_brdf_is_affine_in_and_a_tint_is_not():
    _, fam = _corpus()
    plastics = [m for m in fam["classic"] if rc.reflectance_paths(m)]
    assert plastics and all(rc.affine_slot(m) == ("diffuse",) for m in plastics[:3])
    assert rc.affine_slot(fam["sheen"][0]) == ("base_color",)
    tinted = fam["tinted_coat"][0]
    assert ("tint",) in rc.reflectance_paths(tinted)
    assert not rc.is_affine_in(tinted, ("tint",))             # Beer–Lambert: through a logarithm
    assert rc.affine_slot(tinted) != ("tint",)


def test_a_replaced_reflectance_changes_only_that_field():
    _, fam = _corpus()
    m = fam["car_paint"][0]
    slot = rc.affine_slot(m)
    new = rc.recoloured(TrainingMaterial(m.name, m, True), slot, np.full(REFLECTANCE_GRID_NM.size, 0.25)).brdf
    assert rc.reflectance_at(new, slot).values == (0.25,) * REFLECTANCE_GRID_NM.size
    changed = [f.name for f in dataclasses.fields(m) if getattr(m, f.name) != getattr(new, f.name)]
    assert changed == [slot[0]]


def test_the_recombined_input_is_what_the_renderer_gives_the_recoloured_material():
    from specgen_addon.photo import sphere_image as input_image

    corpus, fam = _corpus()
    m = fam["classic"][0] if rc.affine_slot(fam["classic"][0]) else fam["sheen"][0]
    slot = rc.affine_slot(m)
    pool = rc.spectrum_pool([TrainingMaterial(x.name, x, True) for x in corpus])
    values = pool[len(pool) // 2]
    pair = rc.render_affine_pair(m, slot)
    direct = input_image.render_input(rc.recoloured(TrainingMaterial(m.name, m, True), slot, values).brdf)
    combined = rc.combine(pair, values)
    assert combined.shape == direct.shape == (128, 128, 3)
    assert np.abs(combined - direct).max() <= 1e-5 * direct.max()
    other = input_image.render_input(m)                          # and the swap did change the photo
    assert np.abs(other - direct).max() > 1e-2 * direct.max()


def test_the_pool_holds_only_the_given_materials_spectra():
    corpus, _ = _corpus()
    pool = rc.spectrum_pool([TrainingMaterial(m.name, m, True) for m in corpus])
    have = {tuple(rc.reflectance_at(m, p).values) for m in corpus for p in rc.reflectance_paths(m)}
    assert len(pool) == len(have) and {tuple(v) for v in pool} == have


def _source(p: float, n: int = 4, size: int = 8):
    _, fam = _corpus()
    mats = [TrainingMaterial(m.name, m, True) for m in fam["classic"][:n]]
    rng = np.random.default_rng(3)
    slots = [rc.affine_slot(m.brdf) for m in mats]
    pairs = [None if s is None else rng.random((2, rc.BANDS_NM.size, 16, 16)).astype(np.float16) for s in slots]
    pool = rng.random((5, REFLECTANCE_GRID_NM.size))
    images = [np.zeros((10, 3, size, size), np.float16) for _ in mats]
    return mats, images, rc.RecolourSource(slots, pairs, pool, p)


def test_a_recoloured_draw_takes_a_pool_spectrum_and_its_recombined_input():
    mats, images, src = _source(1.0)
    mset = MaterialSet(mats, images, recolour=src)
    rng = np.random.default_rng(0)
    out_mats, out_imgs = _draw(rng, mset, len(mats), 1.0, 1, "mix")
    pool = {tuple(v) for v in src.pool}
    for m, img in zip(out_mats, out_imgs):
        i = [x.name for x in mats].index(m.name)
        if src.pairs[i] is None:
            assert m is mats[i]
            continue
        values = rc.reflectance_at(m.brdf, src.slots[i]).values
        assert tuple(values) in pool
        candidates = [rc.recoloured_input(src.pairs[i], np.array(values), png, 8) for png in (False, True)]
        assert any(np.array_equal(img, c) for c in candidates)
    assert any(src.pairs[[x.name for x in mats].index(m.name)] is not None for m in out_mats)


def test_recolouring_keeps_each_step_a_pure_function_of_seed_and_step():
    from specgen_addon.model import Config

    mats, images, src = _source(0.5)
    mset = MaterialSet(mats, images, recolour=src)
    tcfg = TrainConfig(spectral_materials_per_step=3, rgb_materials_per_step=0, angles_per_material=16,
                       wavelengths_per_angle=2, lighting="mix", recolour_p=0.5)
    mcfg = Config(image_size=16, encoder_channels=(8, 16))
    a, _ = make_step_batches(tcfg, mcfg, mset, MaterialSet([], []), 7)
    b, _ = make_step_batches(tcfg, mcfg, mset, MaterialSet([], []), 7)
    assert np.array_equal(a.images, b.images) and np.array_equal(a.target, b.target)


@pytest.mark.parametrize("bad, message", [
    ({"recolour_p": 1.5}, "recolour_p must be a number in"),
    ({"recolour_p": "half"}, "recolour_p must be a number in"),
    ({"recolour_p": 0.5, "lighting": "variants"}, "recolour_p needs lighting"),
])
def test_bad_recolour_settings_are_refused(bad, message):
    with pytest.raises(SpecGenError, match=message):
        TrainConfig.from_dict(bad)


def test_a_reflectance_source_is_kept_when_it_is_the_only_one():
    r = Reflectance("x", (0.5,) * REFLECTANCE_GRID_NM.size)
    assert rc.reflectance_paths(r) == [()]
    assert rc.with_reflectance(r, (), rc._ONE) is rc._ONE


def test_the_pair_cache_renders_once_and_loads_slots_pairs_and_pool(tmp_path):
    _, fam = _corpus()
    mats = [TrainingMaterial(m.name, m, True) for m in (fam["lobes"][0], fam["tinted_coat"][0])]
    cache = rc.AffinePairCache(tmp_path)
    assert cache.missing(mats) == mats
    cache.fill(mats, workers=1)
    assert cache.missing(mats) == []
    stamp = [cache.path(m).stat().st_mtime_ns for m in mats]
    cache.fill(mats, workers=1)                                   # nothing left to render
    assert [cache.path(m).stat().st_mtime_ns for m in mats] == stamp
    src = cache.source(mats, 0.25)
    assert src.p == 0.25 and src.slots[0] == rc.affine_slot(mats[0].brdf) == ("diffuse",)
    assert src.pairs[0].shape == (2, rc.BANDS_NM.size, 128, 128) and src.pairs[0].dtype == np.float16
    assert (src.pairs[1] is None) == (rc.affine_slot(mats[1].brdf) is None)
    assert len(src.pool) == len(rc.spectrum_pool(mats))


def test_a_recoloured_copy_reuses_its_originals_lobe_quadrature():
    from specgen_addon.corpus.families import lobes, thin_film

    _, fam = _corpus()
    wi, wo = rc._probe_points(8)
    checked = 0
    for m, cached in ((fam["lobes"][0], lobes._lobe_albedo), (fam["thin_film"][0], thin_film._albedo)):
        slot = rc.affine_slot(m)
        if slot is None:
            continue
        m.eval(wi, wo)
        size = cached.cache_info().currsize
        copy = rc.recoloured(TrainingMaterial(m.name, m, True), slot, np.full(REFLECTANCE_GRID_NM.size, 0.3)).brdf
        copy.eval(wi, wo)
        assert cached.cache_info().currsize == size
        checked += 1
    assert checked >= 1                                           # the lobes material at least
