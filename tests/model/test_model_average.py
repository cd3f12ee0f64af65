"""Weight averaging after the fact (``average-weights``): the mean of weights files and checkpoints."""

from __future__ import annotations

import pytest
import torch

from specgen_addon.cli.app import main as cli_main
from specgen_addon.common.errors import WeightsError
from specgen_addon.model import Config, SpecGen, load_weights, save_weights
from specgen_addon.model.average import average_models
from tiny_model import TINY_MODEL

SMALL = TINY_MODEL


def two_files(tmp_path):
    torch.manual_seed(0)
    a, b = SpecGen(Config(**SMALL)), SpecGen(Config(**SMALL))
    pa = save_weights(a, tmp_path / "a.pt")
    # b as a training checkpoint, the form a run leaves every few hundred steps
    pb = tmp_path / "checkpoint.pt"
    torch.save({"model": b.state_dict(), "model_config": b.cfg.to_dict(), "step": 7, "optimizer": {}}, pb)
    return a, b, pa, pb


def test_average_is_the_element_wise_mean_of_weights_and_checkpoints(tmp_path):
    a, b, pa, pb = two_files(tmp_path)
    mean = average_models([pa, pb]).state_dict()
    sa, sb = a.state_dict(), b.state_dict()
    for k in sa:
        assert torch.allclose(mean[k], (sa[k] + sb[k]) / 2, atol=1e-7), k
    # provenance: the latest source's record (the checkpoint at step 7), and what was averaged
    meta = average_models([pa, pb]).meta
    assert meta["steps"] == 7 and meta["averaged_steps"] == [0, 7] and len(meta["averaged_from"]) == 2


def test_average_weights_command_writes_the_mean_and_refuses_bad_input(tmp_path, capsys):
    a, b, pa, pb = two_files(tmp_path)
    out = tmp_path / "avg.pt"
    assert cli_main(["average-weights", str(pa), str(pb), "-o", str(out)]) == 0
    w = "encoder.fc.weight"
    assert torch.allclose(load_weights(out).state_dict()[w], (a.state_dict()[w] + b.state_dict()[w]) / 2)
    assert cli_main(["average-weights", str(pa), str(pb), "-o", str(out)]) == 2           # exists
    assert "already exists" in capsys.readouterr().err
    assert cli_main(["average-weights", str(pa), "-o", str(tmp_path / "one.pt")]) == 2   # one source
    assert "at least two" in capsys.readouterr().err
    assert cli_main(["average-weights", str(pa), str(tmp_path / "no.pt"), "-o", str(tmp_path / "x.pt")]) == 2
    assert "not found" in capsys.readouterr().err
    assert not (tmp_path / "one.pt").exists() and not (tmp_path / "x.pt").exists()


def test_weights_of_different_models_are_not_averaged(tmp_path):
    pa = save_weights(SpecGen(Config(**SMALL)), tmp_path / "a.pt")
    pb = save_weights(SpecGen(Config(**{**SMALL, "mlp_hidden": (8, 8)})), tmp_path / "b.pt")
    with pytest.raises(WeightsError, match="another model configuration"):
        average_models([pa, pb])
