"""Per-family evaluation: rows per family of the mixed test split, and the RGL rows."""

from __future__ import annotations

import numpy as np
import pytest

from specgen_addon.corpus.generate import material_family
from specgen_addon.common.errors import SpecGenError
from specgen_addon.evaluation.trained_network import (evaluate_families, format_family_results, mixed_split_materials,
                                         mixed_test_materials)


@pytest.mark.slow
def test_mixed_test_materials_are_held_out_and_grouped_by_family():
    mats = mixed_test_materials(2, ["sheen", "thin_film"])
    assert [material_family(m) for m in mats].count("sheen") == 2
    assert [material_family(m) for m in mats].count("thin_film") == 2
    assert all(m.split == "test" for m in mats)


@pytest.mark.slow
def test_val_materials_share_no_material_with_the_test_materials():
    val = mixed_split_materials(2, ["thin_film"], "val")
    assert len(val) == 2 and all(m.split == "val" and material_family(m) == "thin_film" for m in val)
    assert not {m.name for m in val} & {m.name for m in mixed_test_materials(2, ["thin_film"])}


def test_skipping_materials_gives_the_next_ones_of_each_family():
    first_three = mixed_split_materials(3, ["sheen", "thin_film"], "test")
    fresh = mixed_split_materials(1, ["sheen", "thin_film"], "test", skip=2)
    by_family = {f: [m.name for m in first_three if material_family(m) == f] for f in ("sheen", "thin_film")}
    assert sorted(m.name for m in fresh) == sorted(names[2] for names in by_family.values())


def test_unknown_split_is_refused_before_the_corpus_is_drawn():
    with pytest.raises(SpecGenError, match="unknown split 'holdout'"):
        mixed_split_materials(1, None, "holdout")


@pytest.mark.slow
def test_a_family_outside_the_training_mix_is_refused_not_scored_as_empty(monkeypatch):
    """A family registered but not in the default mix has no material in the mixed corpus: asking
    to score it says so in one sentence (it used to print an empty table and exit 0)."""
    from specgen_addon.evaluation import trained_network

    monkeypatch.setattr(trained_network, "FAMILY_NAMES", trained_network.FAMILY_NAMES + ("lambert_const",))
    with pytest.raises(SpecGenError, match="'lambert_const' is not in the default training mix"):
        mixed_split_materials(1, ["lambert_const"], "test")
    with pytest.raises(SpecGenError, match="unknown family 'bogus'"):
        mixed_split_materials(1, ["bogus"], "test")


def test_family_rows_average_to_the_family_means(shared_dir):
    rgl = shared_dir / "data" / "rgl" if shared_dir is not None else None
    res = evaluate_families(per_family=1, envs=False, resolution=24, families=["sheen"], rgl_dir=rgl)
    rows = [r for r in res["materials"] if r["family"] == "sheen"]
    assert len(rows) == 1 and np.isfinite(rows[0]["psnr_distant"])
    assert res["families"]["sheen"]["psnr_distant"] == pytest.approx(rows[0]["psnr_distant"])
    if rgl is not None and any(rgl.glob("*.bsdf")):
        assert res["families"]["rgl (real, RGB)"]["n"] == len(list(rgl.glob("*.bsdf")))
    assert "sheen" in format_family_results(res)
    # each oracle is fitted to the band-averaged dB itself, the colour fit from the brightness fit
    assert rows[0]["psnr_brightness_fitted_distant"] >= rows[0]["psnr_distant"] - 1e-9
    assert "brightness fitted" in format_family_results(res)
    assert rows[0]["psnr_colour_fitted_distant"] >= rows[0]["psnr_brightness_fitted_distant"] - 1e-9
    assert "colour (a smooth spectral gain) fitted" in format_family_results(res)
    # every fidelity row comes with its self-reproduction against the input photo
    assert np.isfinite(rows[0]["self_psnr"]) and rows[0]["self_de"] >= 0.0
    assert res["families"]["sheen"]["self_psnr"] == pytest.approx(rows[0]["self_psnr"])
    assert res["means"]["self_de"] == pytest.approx(rows[0]["self_de"])
    assert "self-reproduction dB / ΔE2000" in format_family_results(res)


@pytest.mark.slow
def test_input_env_photographs_the_input_under_that_map(shared_dir):
    rgl = shared_dir / "data" / "rgl" if shared_dir is not None else None   # RGB-only files take eval_rgb
    kw = dict(per_family=1, envs=False, resolution=24, families=["classic"], rgl_dir=rgl)
    canonical = evaluate_families(**kw)
    under_map = evaluate_families(input_env="courtyard", **kw)
    assert canonical["input"] == "canonical" and under_map["input"] == "courtyard"
    # another input image gives another table, so another score against the same truth
    assert under_map["materials"][0]["psnr_distant"] != pytest.approx(canonical["materials"][0]["psnr_distant"], abs=1e-3)
    assert "'courtyard'" in format_family_results(under_map)
    # reproduced in the scene it was photographed in, not the canonical one
    assert under_map["materials"][0]["self_psnr"] != pytest.approx(canonical["materials"][0]["self_psnr"], abs=1e-3)
    assert "courtyard" not in format_family_results(canonical)


def test_evaluate_family_option_scores_only_that_family_and_skips_rgl(monkeypatch, tmp_path):
    """``evaluate --families N --family sheen`` hands the family list on and leaves out the RGL rows."""
    import specgen_addon.evaluation.trained_network as ev
    from specgen_addon.cli.app import main as cli_main

    seen = {}

    def fake_families(**kw):   # its result only reaches the patched formatter below
        seen.update(kw)
        return {}

    monkeypatch.setattr(ev, "evaluate_test_split", lambda **kw: {"materials": [], "psnr_mean": 0.0})
    monkeypatch.setattr(ev, "format_results", lambda res: "")
    monkeypatch.setattr(ev, "evaluate_families", fake_families)
    monkeypatch.setattr(ev, "format_family_results", lambda res: "")
    assert cli_main(["evaluate", "--families", "200", "--family", "sheen", "--family", "lobes",
                     "--no-envs", "--no-refine", "--limit", "1", "--quiet"]) == 0
    assert seen["families"] == ["sheen", "lobes"] and seen["per_family"] == 200 and seen["rgl_dir"] is None
    assert seen["split"] == "test"
    seen.clear()
    assert cli_main(["evaluate", "--families", "2", "--family-split", "train", "--no-envs", "--no-refine",
                     "--limit", "1", "--quiet"]) == 0
    assert seen["split"] == "train" and seen["rgl_dir"] is None    # the real files are held-out test data
    seen.clear()
    assert cli_main(["evaluate", "--families", "1", "--no-envs", "--no-refine", "--limit", "1",
                     "--quiet"]) == 0
    assert seen["families"] is None and seen["rgl_dir"] is not None


@pytest.mark.parametrize("input_env", [None, "courtyard"])
def test_a_material_reproduces_its_own_photo_and_another_material_does_not(input_env):
    """The self-reproduction scores a BRDF in the very scene its input photo was taken in: the true
    material gives its photo back (to float32 rounding), another material does not."""
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.evaluation.protocol import input_lighting_under, input_under_environment, test_materials
    from specgen_addon.evaluation.self_reproduction import self_reproduction
    from specgen_addon.photo.photo_lighting import InputLighting

    truth, other = test_materials(2)
    if input_env is None:
        photo, light = input_image.render_input(truth), InputLighting()
    else:
        photo, light = input_under_environment(truth, input_env), input_lighting_under(input_env)
    own, wrong = self_reproduction(truth, photo, light), self_reproduction(other, photo, light)
    assert own.psnr_db > 80.0 and own.delta_e2000 < 0.01
    assert wrong.psnr_db < 40.0 and wrong.delta_e2000 > 1.0


@pytest.mark.slow
def test_family_split_train_scores_training_materials_and_says_so():
    res = evaluate_families(per_family=1, envs=False, resolution=16, families=["classic"], split="train",
                            self_reproduction=False)
    (row,) = res["materials"]
    assert row["material"] == mixed_split_materials(1, ["classic"], "train")[0].name
    assert res["split"] == "train" and "'train' split" in format_family_results(res)
