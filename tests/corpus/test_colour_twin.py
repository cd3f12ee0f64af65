"""The colour twin (specgen_addon.corpus.colour_twin): same colours, Otsu 2018 spectra, nothing else changed."""

from __future__ import annotations

import dataclasses

import numpy as np

from specgen_addon.corpus.colour_twin import colour_twin, reflectance_twin
from specgen_addon.corpus.generate import generate_mixed_corpus
from specgen_addon.corpus.material import Conductor, Reflectance
from specgen_addon.corpus.spectra_sources import REFLECTANCE_GRID_NM, measured_spectra
from specgen_addon.spectral.spectra import reflectance_to_linear_srgb
from specgen_addon.spectral.otsu2018 import otsu2018_reflectance, xyz_of_reflectance

GRID = np.arange(360.0, 831.0, 5.0)


def _xyz(r: Reflectance) -> np.ndarray:
    return xyz_of_reflectance(r.at(GRID), GRID)


def test_a_measured_reflectance_keeps_its_colour_and_changes_its_spectrum():
    s = next(m for m in measured_spectra() if m.id.startswith("CIE TCS"))
    r = Reflectance(s.id, tuple(float(v) for v in s.values))
    twin = reflectance_twin(r)
    np.testing.assert_allclose(_xyz(twin), _xyz(r), atol=2e-3)
    # a measured spectrum is not an Otsu 2018 one: the twin is a metamer, not a copy
    assert np.abs(np.asarray(twin.values) - np.asarray(r.values)).max() > 0.01


def test_an_otsu_reflectance_is_its_own_twin():
    values = otsu2018_reflectance(np.array([0.2, 0.18, 0.08]), REFLECTANCE_GRID_NM)
    r = Reflectance("made by Otsu 2018", tuple(float(v) for v in values))
    np.testing.assert_allclose(reflectance_twin(r).values, r.values, atol=2e-3)


def test_the_twin_of_each_family_changes_only_its_reflectances(tiny_corpus):
    mats = tiny_corpus
    seen = set()
    for m in mats:
        twin = colour_twin(m)
        assert type(twin) is type(m) and twin.name == m.name and twin.split == m.split
        for field in dataclasses.fields(m):
            a, b = getattr(m, field.name), getattr(twin, field.name)
            if isinstance(a, Reflectance):
                # the same colour (saturated ones too: Otsu 2018's clipping is undone), in a second
                # colour path (the project's sRGB matrix on the corpus grid)
                rgb_a = reflectance_to_linear_srgb(np.asarray(a.values), REFLECTANCE_GRID_NM)
                rgb_b = reflectance_to_linear_srgb(np.asarray(b.values), REFLECTANCE_GRID_NM)
                assert np.abs(rgb_b - rgb_a).max() <= 2e-3 * max(rgb_a.max(), 0.05), field.name
                assert min(b.values) >= 0.0 and max(b.values) <= 1.0
            elif isinstance(a, (float, int, str, Conductor)):
                assert a == b, field.name
        seen.add(type(m).__name__)
    assert len(seen) >= 5   # the families, each rebuilt by dataclasses.replace


def test_a_saturated_colour_clipped_by_otsu_is_restored(tiny_corpus):
    """A saturated magenta-red, whose Otsu 2018 spectrum clipping to [0, 1] makes 4 % less red."""
    m = next(x for x in tiny_corpus if x.name == "mat0042")
    r = m.sheen_color
    clipped = otsu2018_reflectance(_xyz(r), REFLECTANCE_GRID_NM)
    assert np.abs(xyz_of_reflectance(np.interp(GRID, REFLECTANCE_GRID_NM, clipped), GRID) - _xyz(r)).max() > 5e-3
    np.testing.assert_allclose(_xyz(reflectance_twin(r)), _xyz(r), atol=1e-4)


def test_the_twin_renders_the_same_colour_under_d65(tiny_corpus):
    """Every BRDF evaluation of the twin matches the material's RGB (a renderer's colour) closely,
    while its spectral values differ: what metamerism hides from an RGB photo."""
    m = next(x for x in tiny_corpus if type(x).__name__ == "Sheen")
    twin = colour_twin(m)
    rng = np.random.default_rng(0)
    wi = rng.normal(size=(64, 3)); wi[:, 2] = np.abs(wi[:, 2]); wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = rng.normal(size=(64, 3)); wo[:, 2] = np.abs(wo[:, 2]); wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    rgb, rgb_twin = m.eval_rgb(wi, wo), twin.eval_rgb(wi, wo)
    assert np.abs(rgb_twin - rgb).max() <= 0.02 * np.abs(rgb).max()
    w = np.array([450.0, 550.0, 650.0])
    assert not np.allclose(m.eval(wi, wo, w), twin.eval(wi, wo, w), rtol=1e-3)


def test_a_twin_of_a_non_material_is_the_value_itself():
    assert colour_twin(0.5) == 0.5
    assert colour_twin(None) is None
    gold = Conductor("Au")
    assert colour_twin(gold) is gold          # metals are kept: the module's stated optimism


def test_replace_reflectances_replaces_every_reflectance_and_keeps_every_other_parameter():
    from specgen_addon.corpus.colour_twin import replace_reflectances

    grey = Reflectance("grey", tuple(0.5 for _ in REFLECTANCE_GRID_NM))
    for mat in generate_mixed_corpus(40, 1):
        seen: list[str] = []

        def to_grey(r: Reflectance) -> Reflectance:
            seen.append(r.source)
            return grey

        new = replace_reflectances(mat, to_grey)
        originals = [f for f in dataclasses.fields(mat) if isinstance(getattr(mat, f.name), Reflectance)]
        assert len(seen) >= len(originals)                   # nested ones (a coat's) count too
        assert (new is mat) == (not seen)                    # nothing to replace: the same object
        for f in dataclasses.fields(mat):
            old = getattr(mat, f.name)
            if isinstance(old, Reflectance):
                assert getattr(new, f.name) is grey
            elif not dataclasses.is_dataclass(old):
                assert getattr(new, f.name) == old          # roughness, films, metals' names, ...
