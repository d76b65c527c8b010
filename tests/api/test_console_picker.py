"""The console's file picker offers every format the server reads."""

from __future__ import annotations

import re
from pathlib import Path

from server.cloud_io import FORMATS

INDEX = Path(__file__).resolve().parents[2] / "web_static" / "index.html"


def test_the_cloud_picker_accepts_every_format_the_server_reads() -> None:
    m = re.search(r'<input id="cloud-file" type="file" accept="([^"]+)"', INDEX.read_text())
    assert m is not None, "no cloud file picker in index.html"
    offered = {ext.strip().lstrip(".") for ext in m.group(1).split(",")}
    assert offered == set(FORMATS), sorted(offered ^ set(FORMATS))
