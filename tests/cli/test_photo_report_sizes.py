"""What ``infer`` and batch.py print about the photo's side files says where each went and its size."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from types import SimpleNamespace

from specgen_addon.cli.photo_args import print_photo_report
from specgen_addon.photo.sphere_image import PhotoSource

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "sphere.png"


def test_the_circle_preview_is_reported_with_its_path_and_size(tmp_path, capsys):
    source = PhotoSource(EXAMPLE)
    generated = SimpleNamespace(crop=source.crop(), canonical_input=None, network_reproduction=None)
    preview = tmp_path / "circle.png"
    print_photo_report(generated, argparse.Namespace(circle_preview=preview, overwrite=False), source)
    out = capsys.readouterr().out
    size = re.search(rf"wrote {re.escape(str(preview))} \(.*, ([\d.]+) kB\)", out)
    assert size is not None, out
    assert abs(float(size.group(1)) - preview.stat().st_size / 1e3) < 0.1
