import numpy as np
import pytest

from specgen_addon.common.errors import BRDFFormatError
from specgen_addon.brdf.formats import detect_format, load_brdf
from specgen_addon.brdf.formats.merl import MERL_SCALE, MERLData, read_merl, write_merl
from specgen_addon.brdf.table import BRDFTable


@pytest.fixture(scope="module")
def raw():
    r = np.random.default_rng(0).random((3, 90, 90, 180)) * 1500
    r[:, 89, 89, 5] = -1.0  # invalid marker, as MERL stores at grazing angles
    return r


def test_round_trip_is_bit_exact(tmp_path, raw):
    p = write_merl(tmp_path / "m.binary", MERLData(raw))
    back = read_merl(p)
    assert back.raw.tobytes() == raw.astype("<f8").tobytes()
    p2 = write_merl(tmp_path / "m2.binary", back)
    assert p.read_bytes() == p2.read_bytes()


def test_layout_is_planar_int32_dims_then_float64(tmp_path, raw):
    p = write_merl(tmp_path / "m.binary", MERLData(raw))
    data = p.read_bytes()
    assert np.frombuffer(data[:12], "<i4").tolist() == [90, 90, 180]
    n = 90 * 90 * 180
    blue_first = np.frombuffer(data[12 + 2 * n * 8: 12 + 2 * n * 8 + 8], "<f8")[0]
    assert blue_first == raw[2, 0, 0, 0]
    # [θh][θd][φd] order: the second float is φd index 1.
    assert np.frombuffer(data[20:28], "<f8")[0] == raw[0, 0, 0, 1]


def test_table_applies_channel_scales_and_masks_invalid(tmp_path, raw):
    t = load_brdf(write_merl(tmp_path / "m.binary", MERLData(raw)))
    assert isinstance(t, BRDFTable) and not t.is_spectral
    assert np.allclose(t.values[1, 2, 3], raw[:, 1, 2, 3] * MERL_SCALE, rtol=1e-6)
    assert np.all(t.values[89, 89, 5] == 0)
    assert t.metadata["invalid_entries"] == 1
    assert t.values.min() >= 0


def test_table_to_merl_and_back(tmp_path):
    t = BRDFTable.tabulate(lambda a, b, c: np.stack([np.cos(a), np.cos(b), 0.5 + 0 * c], -1))
    back = load_brdf(write_merl(tmp_path / "t.binary", t))
    assert np.allclose(back.values, t.values, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("mutate, message", [
    (lambda b: b[:1000], "truncated"),
    (lambda b: b[:8], "truncated"),
    (lambda b: np.array([90, 90, 90], "<i4").tobytes() + b[12:], "dims"),
    (lambda b: b + b"extra", "oversized"),
])
def test_bad_files_raise_named_error_with_path(tmp_path, raw, mutate, message):
    good = write_merl(tmp_path / "m.binary", MERLData(raw)).read_bytes()
    bad = tmp_path / "bad.binary"
    bad.write_bytes(mutate(good))
    with pytest.raises(BRDFFormatError, match=message) as err:
        read_merl(bad)
    assert "bad.binary" in str(err.value)


def test_unknown_file_kind_is_refused(tmp_path):
    p = tmp_path / "notes.txt"
    p.write_text("hello")
    with pytest.raises(BRDFFormatError, match="unknown BRDF format"):
        detect_format(p)
