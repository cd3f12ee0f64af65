"""Generate has one front door (generate.pipeline.generate): the CLI's table and the panel's and
batch.py's baked lookup come from the same call, ``out_dir`` adding only the bake."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from specgen_addon.bake.lookup import load_atlas_info
from specgen_addon.common.errors import OutputExistsError, SpecGenError
from specgen_addon.generate.pipeline import generate
from specgen_addon.model import DEFAULT_WEIGHTS

REPO = Path(__file__).resolve().parents[2]
PHOTO = str(REPO / "examples" / "sphere.png")
WL = np.linspace(420.0, 680.0, 3)


@pytest.fixture(scope="module")
def weights() -> Path:
    if not Path(DEFAULT_WEIGHTS).is_file():
        pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
    return Path(DEFAULT_WEIGHTS)


def test_baking_into_a_folder_keeps_the_table_the_cli_gets(weights, tmp_path):
    alone = generate(PHOTO, refine=False, wavelengths_nm=WL)
    seen = []
    baked = generate(PHOTO, refine=False, wavelengths_nm=WL, out_dir=tmp_path, name="ball", n_phi_d=45,
                     save_table=True, progress=seen.append)
    assert alone.lookup is None
    np.testing.assert_array_equal(baked.table.values, alone.table.values)
    info = load_atlas_info(tmp_path / "ball_lookup.json")
    assert info.n_coeffs == baked.lookup.n_coeffs and info.n_phi_d == 45
    assert (tmp_path / "ball.npz").is_file()
    assert max(seen) == pytest.approx(1.0) and min(seen) < 0.8 <= seen[-2]   # generation 0–0.8, bake to 1


def test_existing_outputs_and_bad_names_are_refused_before_any_work(weights, tmp_path):
    (tmp_path / "ball_lookup.json").write_text("{}")
    seen = []
    with pytest.raises(OutputExistsError, match="ball_lookup.json: already exists"):
        generate(PHOTO, wavelengths_nm=WL, out_dir=tmp_path, name="ball", overwrite=False, progress=seen.append)
    with pytest.raises(SpecGenError, match="BRDF name"):
        generate(PHOTO, wavelengths_nm=WL, out_dir=tmp_path / "new", name="a/b", progress=seen.append)
    assert seen == [] and not (tmp_path / "new").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ball_lookup.json"]


class _Stop(Exception):
    """Raised by the stand-in network: the test has what it asked for."""


@pytest.fixture
def asked_of_network(monkeypatch) -> dict:
    """What the pipeline asks the network for (its keywords), the network itself never run."""
    from specgen_addon.generate import pipeline

    asked: dict = {}

    def network(*_args, **kwargs):
        asked.update(kwargs)
        raise _Stop

    monkeypatch.setattr(pipeline, "generate_brdf", network)
    return asked


@pytest.mark.parametrize("every_band,gap", [(False, "default"), (True, None)])
def test_generate_asks_the_network_for_bands_40_nm_apart_unless_every_band(asked_of_network, every_band, gap):
    from specgen_addon.generate import pipeline

    with pytest.raises(_Stop):
        generate(PHOTO, refine=False, every_band=every_band)
    assert asked_of_network["band_gap_nm"] == (pipeline.NETWORK_BAND_GAP_NM if gap == "default" else None)
    assert pipeline.NETWORK_BAND_GAP_NM == 40.0


@pytest.mark.parametrize("latent_fit", [False, True])
def test_no_backend_chosen_takes_torch_for_the_latent_fit(monkeypatch, asked_of_network, latent_fit):
    """batch.py and the panel leave the backend to the pipeline: onnx where installed, but the
    latent fit needs gradients, so a run with it takes torch instead of refusing itself."""
    from specgen_addon.generate import pipeline

    monkeypatch.setattr(pipeline, "choose_backend", lambda: "onnx")
    with pytest.raises(_Stop):
        generate(PHOTO, refine=False, backend=None, latent_fit=latent_fit)
    assert asked_of_network["backend"] == ("torch" if latent_fit else "onnx")
